"""Cases with contact between Lagrangian bodies (issue 11), each checked against its reference by its
own [check]; on 2 ranks equal to 1 rank bit for bit; a checkpoint continues bit for bit."""
import json
import shutil

import h5py
import numpy as np
import pytest

from tests.cases.test_cases import CASES, case_variant, run_case
from tests.cases.test_coupled_cases import assert_same_steps
from tests.conftest import immerse


def continue_from_first_checkpoint(case, one, cont):
    """A copy of the run ``one`` continued from its first checkpoint into ``cont``; asserts its last
    output step equals ``one``'s bit for bit. Returns ``cont``."""
    ckpt = sorted((one / "checkpoints").glob("checkpoint_*.h5"))[0]
    shutil.copytree(one, cont, symlinks=True)
    r = immerse("run", case, "--out", cont, "--restart", cont / "checkpoints" / ckpt.name)
    assert r.returncode == 0, r.stdout + r.stderr
    assert_same_steps(one, cont, slice(-1, None), roles=("lagrange",))
    return cont


def test_bars_impact(tmp_path):
    """Two elastic bars, 10 m/s against one at rest (cases/bars_impact): contact for 2 L / c =
    39.50 us at rho c v0 / 2 = 197.5 MPa, then the velocities swap; explicit dual-pass mortar contact
    (measured: 39.59 us, 197.53 MPa, 0.74 % of v0 left in the striker, 0.14 % of the energy taken by
    the contact, momentum 1.0e-14, energy 1.0e-15)."""
    out, s = run_case("bars_impact", tmp_path)
    assert set(s["check"]["metrics"]) == {"contact_duration", "interface_stress", "velocity_striker_rel",
                                          "velocity_target_rel", "contact_dissipation_rel",
                                          "momentum_balance_rel", "energy_balance_rel"}
    # summary.json's contact balances: the energy the contact took (the check's figure), the largest
    # force (measured 1.26 x the plateau rho c v0 / 2 x 0.005 m: the first step in contact stops the
    # interface nodes within one step), the 7 multipliers
    c = s["contact"]["lagrange"]
    assert c["dissipated_rel"] == s["check"]["metrics"]["contact_dissipation_rel"]["value"]
    assert c["work"] < 0 and 1.0 < c["force_max"] / (197.5e6 * 0.005) < 1.4 and c["active_max"] == 7
    with h5py.File(out / "diagnostics.h5") as h:
        t, active = h["time"][...], h["lagrange.contact_active"][...]
    # the 3 + 4 interface nodes of both passes are active in contact, none after the release
    assert active[(t > 1e-6) & (t < 39e-6)].min() == 7 and active[t > 41e-6].max() == 0
    # the output's contact pressure: on those 7 nodes within 1 % of rho c v0 / 2 at every output in
    # contact (measured 0.29 % at worst), nowhere after the release
    from orchestrator import output

    # and the gap: closed on them in contact (the stabilized gap is 0: measured |g| 2.4e-10 m at most),
    # opening at the bars' relative speed after (measured 10.00 m/s over the last two outputs)
    gaps = []
    for time, _, index in output.read_steps(out, "lagrange")[1:]:
        pd = output.read_step(out, "lagrange", index)[1]
        p, g = pd["contact_pressure"], pd["contact_gap"]
        if time < 39e-6:
            assert np.count_nonzero(p) == 7 and np.abs(p[p != 0] / 197.5e6 - 1).max() < 0.01, time
            assert np.abs(g[p != 0]).max() < 1e-9, time
            on = p != 0
        else:
            assert not p.any(), time
            gaps.append((time, g[on]))
    (t0, g0), (t1, g1) = gaps[-2:]   # (outputs at the first step reaching each 5 us: their own times)
    assert np.abs((g1 - g0) / (t1 - t0) / 10.0 - 1).max() < 1e-3


@pytest.mark.slow
def test_bars_impact_on_two_ranks_and_from_a_checkpoint(tmp_path):
    """2 ranks (the bars' nodes on both; every rank solves the gathered contact) equal 1 rank bit for
    bit; a checkpoint at 30 us (in contact) continues bit for bit."""
    case = case_variant(tmp_path, "bars_impact",
                        ("output_interval = 5.0e-6", "output_interval = 5.0e-6\ncheckpoint_interval = 30.0e-6"))
    one, two = tmp_path / "one", tmp_path / "two"
    for out, ranks in ((one, "lagrange=1"), (two, "lagrange=2")):
        r = immerse("run", case, "--out", out, "--ranks", ranks)
        assert r.returncode == 0, r.stdout + r.stderr
    assert_same_steps(one, two, roles=("lagrange",))
    # sums over the ranks in another order: equal to 1e-12, or 1e-14 absolute where they vanish (the
    # y momentum: 1.7e-17 and 1.8e-17 against the bar's 3.9 kg m/s)
    fa, fb = (json.loads((d / "summary.json").read_text())["final"] for d in (one, two))
    assert fa.keys() == fb.keys()
    for k in fa:
        assert fb[k] == pytest.approx(fa[k], rel=1e-12, abs=1e-14), k
    with h5py.File(one / "diagnostics.h5") as a, h5py.File(two / "diagnostics.h5") as b:
        assert np.array_equal(a["lagrange.contact_force_x"][...], b["lagrange.contact_force_x"][...])
    cont = continue_from_first_checkpoint(case, one, tmp_path / "cont")
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in (one, cont))
    assert sa["final"] == sb["final"]


@pytest.mark.slow
def test_block_on_incline_slides_at_newtons_rate(tmp_path):
    """Coulomb friction mu = 0.2 (cases/block_on_incline): at 20 degrees the block accelerates at
    g (sin - mu cos) = 1.511541 m/s^2 (its own check; measured 3.5e-5 off over 0.02-0.1 s)."""
    out, s = run_case("block_on_incline", tmp_path)
    with h5py.File(out / "diagnostics.h5") as h:
        assert h["lagrange.contact_sliding"][-1] > 0 and h["lagrange.contact_work"][-1] < 0  # friction dissipates
    # the output's slip (summed over the steps in contact): the block's 5 bottom nodes slid as far as
    # they moved along the incline, measured 0.05 % (nodes 2-4) and 0.49 % (node 1) less; the uphill
    # corner 2.1 % less: the landing's ringing lifts it off now and then (it carries the least
    # pressure: friction's overturning moment). The incline's nodes slid as much under it.
    from orchestrator import output

    _, _, index = output.read_steps(out, "lagrange")[-1]
    pd = output.read_step(out, "lagrange", index)[1]
    slip, u = pd["contact_slip"][:15], pd["displacement"][:15, 0]
    on = slip > 0
    assert on.sum() == 5
    ratio = slip[on] / u[on]
    assert np.abs(ratio[1:] - 1).max() < 0.01 and 0.96 < ratio[0] < 1.001, ratio


@pytest.mark.slow
def test_block_sticks_below_the_friction_angle(tmp_path):
    """At 10 degrees (tan 0.176 < mu = 0.2; cases/block_on_incline_stick) the block, after its landing,
    does not slide: its own check holds the slip of its nodes over 0.15-0.3 s to round-off (measured
    5.0e-15 m with the default assumed-strain stiffness, whose landing settles by 0.15 s; the contact
    seeing the held incline's predicted velocities, planted, fails it: 4.5e-13 m), while its momentum
    keeps swinging with its elastic ringing. Without friction it slides at
    g sin 10 = 1.703479 m/s^2 (measured 7.8e-6 off)."""
    out, s = run_case("block_on_incline_stick", tmp_path)
    assert set(s["check"]["metrics"]) == {"slip_max", "energy_balance_rel", "momentum_balance_rel"}
    assert s["check"]["reported"]["speed_max"] > 1e-7   # (it rings: measured 7.8e-6 m/s)
    case = case_variant(tmp_path, "block_on_incline_stick", ("friction = 0.2", "friction = 0.0"),
                        ("end_time = 0.3", "end_time = 0.1"), ("window = [0.15, 0.3]", "window = [0.02, 0.1]"),
                        ("metrics.slip_max = { reference = 0.0, tolerance = 2e-14 }",
                         "metrics.acceleration = { reference = 1.703479, tolerance = 3e-5 }"))  # measured 7.8e-6
    r = immerse("run", case, "--out", tmp_path / "free_out")
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.slow
def test_block_on_incline_3d_slides_along_gravity_at_newtons_rate(tmp_path):
    """3-D Coulomb friction (cases/block_on_incline_3d: two tangents per multiplier, the impulses
    bounded by a disc): gravity tilted 20 degrees towards 30 degrees off x; the block accelerates
    along (cos 30, sin 30) at g (sin 20 - mu cos 20) = 1.511541 m/s^2: its own check on x (measured
    1.9e-5 off 1.309033), here y (1.8e-4 off 0.755771), the magnitude (3.2e-5) and the direction
    (30.005 degrees: an anisotropic bound, a box on the two tangents, would turn it). 2 ranks equal
    1 rank bit for bit."""
    out, s = run_case("block_on_incline_3d", tmp_path)
    with h5py.File(out / "diagnostics.h5") as h:
        t = h["time"][...]
        w = (t >= 0.02) & (t <= 0.1)
        ax, ay = (np.polyfit(t[w], h[f"lagrange.momentum_{c}"][w] / 0.5, 1)[0] for c in "xy")
        assert h["lagrange.contact_sliding"][-1] > 0 and h["lagrange.contact_work"][-1] < 0
    assert ay == pytest.approx(0.755771, rel=1e-3)                      # measured 1.8e-4
    assert np.hypot(ax, ay) == pytest.approx(1.511541, rel=2e-4)        # measured 3.2e-5
    assert np.degrees(np.arctan2(ay, ax)) == pytest.approx(30.0, abs=0.02)  # measured 0.005
    # on 2 ranks (each rank's boxes decide the nodes near: zone.py) equal to 1 rank bit for bit
    r = immerse("run", CASES / "block_on_incline_3d", "--out", tmp_path / "two", "--ranks", "lagrange=2")
    assert r.returncode == 0, r.stdout + r.stderr
    assert_same_steps(out, tmp_path / "two", roles=("lagrange",))


@pytest.mark.slow
def test_block_on_incline_3d_sticks_below_the_friction_angle(tmp_path):
    """The 3-D block at 10 degrees (tan 0.176 < mu = 0.2), tilted towards 30 degrees off x: after its
    landing no node slides more than 1e-14 m over 0.1-0.3 s (measured 5.4e-16 m, 3.8e-16 m when the
    friction solve took its 10,000 sweeps every step before it stopped on its floor; 4.5e-11 m with it
    capped at 100 sweeps; 2.2e-10 m while J ignored that a step shortened to land on an output time
    has its pressure p dt / dt_force, 4.1e-13 m with the friction solve stopped at 1e-10 of the
    largest slip rate without a warm start)."""
    case = case_variant(tmp_path, "block_on_incline_3d",
                        ("gravity = [2.905726, 1.677621, -9.218442]", "gravity = [1.475256, 0.851740, -9.660964]"),
                        ("end_time = 0.1", "end_time = 0.3"), ("window = [0.02, 0.1]", "window = [0.1, 0.3]"),
                        ("metrics.acceleration = { reference = 1.309033, tolerance = 1e-4 }",
                         "metrics.slip_max = { reference = 0.0, tolerance = 1e-14 }"))
    r = immerse("run", case, "--out", tmp_path / "out")
    assert r.returncode == 0, r.stdout + r.stderr
    m = json.loads((tmp_path / "out" / "summary.json").read_text())["check"]["metrics"]
    assert set(m) == {"slip_max", "energy_balance_rel", "momentum_balance_rel"}


@pytest.mark.slow
def test_ring_self_contact(tmp_path):
    """A thin rubber ring crushed between a held and a driven plate until its walls meet inside
    (cases/ring_self_contact, issue 11): its own check passes (no surface node, at any step, deeper
    than 8 % of the wall into a plate and 6 % into itself: measured 5.4 % and 3.9 % by the contact's
    own measure every step; energy balance within 1e-14, measured 5.9e-15, issue: 1 %), and the
    self contact happened: ring nodes pressed
    by the ring itself at the end (measured 8), the contact's multipliers active then (measured 18).
    Measured at the default alpha 1 with the symmetric J (the earlier J cycled there: alpha 0.01)."""
    out, s = run_case("ring_self_contact", tmp_path)
    m = s["check"]["metrics"]
    assert set(m) == {"penetration_rel", "penetration_self_rel", "self_contact_nodes", "energy_balance_rel"}
    assert m["self_contact_nodes"]["value"] >= 4 and s["check"]["reported"]["self_contact_pressure"] > 0
    with h5py.File(out / "diagnostics.h5") as h:
        assert h["lagrange.contact_active"][-1] > 0
        # the driven plate's reactions and the contact did the work (the ring was at rest)
        assert h["lagrange.external_work"][-1] > 0 and h["lagrange.kinetic_energy"][0] == 0.0


@pytest.mark.slow
def test_impacting_plates(tmp_path):
    """A spinning striker plate, its corner leading, falls at an angle on a free plate
    (cases/impacting_plates, 3-D, hexahedra, frictionless explicit contact): the contact happens
    (measured: from 33.6 us to 118 us and again from 143 us, impulse 1.5689 N s against 1.5716 at 6
    elements through each plate), no surface node of either plate ends up behind the other's surface
    at any step by more than 2 % of an edge (measured 0.92 %, 45.9 um: the mortar gap holds weighted
    over the facets), linear momentum exact (4.5e-15) and the angular momentum with the contact an
    internal pair to 1.24e-8 (the rows on warped quadrilateral facets; the case's bound 4e-8: the
    operators built at the predicted end positions x^n + dt v* instead of x^n give 1.22e-5 and fail,
    measured), energy with the contact's work booked (3.4e-16); `immerse view` draws it."""
    out, s = run_case("impacting_plates", tmp_path)
    assert set(s["check"]["metrics"]) == {"penetration_max_rel", "contact_impulse", "momentum_balance_rel",
                                          "angular_momentum_balance_rel", "energy_balance_rel",
                                          "contact_dissipation_rel"}
    with h5py.File(out / "diagnostics.h5") as h:
        t, active = h["time"][...], h["lagrange.contact_active"][...]
    # the corner strikes first (1 mm at 31 m/s: 32 us), the plates part, and the bent plate swings
    # back into the striker's edge (measured: active 33.6-118.0 us, again from 142.9 us)
    on = active > 0
    assert 30e-6 < t[on][0] < 36e-6 and not on[(t > 125e-6) & (t < 140e-6)].any(), t[on][0]
    assert on[t > 120e-6].any()
    r = immerse("view", out, "--field", "von_mises_stress", "contact_pressure", "--step", "last")
    assert r.returncode == 0, r.stdout + r.stderr
    assert {p.name for p in (out / "pictures").glob("*.png")} == {
        "lagrange_von_mises_stress_000030.png", "lagrange_contact_pressure_000030.png"}


@pytest.mark.slow
def test_friction_slip_continues_from_a_checkpoint(tmp_path):
    """block_on_incline checkpointed at 0.05 s (sliding) and continued: the last step, the slip
    accumulated by friction included, equals the uninterrupted run's bit for bit."""
    case = case_variant(tmp_path, "block_on_incline",
                        ("output_interval = 0.025", "output_interval = 0.025\ncheckpoint_interval = 0.05"))
    one = tmp_path / "one"
    r = immerse("run", case, "--out", one)
    assert r.returncode == 0, r.stdout + r.stderr
    cont = continue_from_first_checkpoint(case, one, tmp_path / "cont")
    from orchestrator import output

    _, _, index = output.read_steps(one, "lagrange")[-1]
    a, b = (output.read_step(d, "lagrange", index)[1]["contact_slip"] for d in (one, cont))
    assert a.max() > 7e-3 and np.array_equal(a, b)
