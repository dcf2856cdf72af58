"""The command loop every solver process runs: join the job, set up the adapter, then obey the
coupler's commands until told to stop. One implementation for every solver role."""
from __future__ import annotations

import argparse
import os
import time as _time
from pathlib import Path

import numpy as np

from adapters import case_file
from adapters import protocol as P
from adapters.registry import coupling_side
from solvers.probes import probes_for


def parse_args(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", required=True, help="the case file the launcher wrote (adapters/case_file.py)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--roles", required=True, help="comma-separated: coupler first")
    ap.add_argument("--role", required=True)
    ap.add_argument("--restart", default=None)
    ap.add_argument("--case-sha256", required=True, help="the SHA-256 of that file's bytes")
    return ap.parse_args(argv)


def restart_file(manifest: Path, role: str) -> Path:
    """The role's own state file named by a coupler checkpoint manifest."""
    import h5py

    with h5py.File(manifest, "r") as h:
        rel = h.attrs[f"file_{role}"]
    return Path(manifest).parent / str(rel)


def pack_surface(adapter) -> np.ndarray:
    """A foreground's surface as one float64 buffer (collective: every rank computes it):
    [ns, nv, nf, node_ids, facets, body, mass, free (ns, dim), x (ns, dim), v (ns, dim)
     (, h, volume (ns,): particles)]."""
    srf = adapter.surface()
    x = adapter.positions()
    v = adapter.velocities()
    ns, dim = x.shape
    facets = np.asarray(srf["facets"])
    free = np.asarray(srf.get("free", np.ones((ns, dim))), dtype=np.float64)
    # a particle foreground (SPH) adds its kernel support h and the particles' volumes
    particles = [[srf["smoothing_length"]], srf["volume"]] if "volume" in srf else []
    return np.concatenate([[ns, facets.shape[1], facets.shape[0]], srf["node_ids"], facets.ravel(),
                           srf["body"], srf["mass"], free.ravel(), x.ravel(), v.ravel(), *particles]).astype(np.float64)


def unpack_surface(buf: np.ndarray, dim: int) -> dict:
    ns, nv, nf = (int(a) for a in buf[:3])
    pos = 3
    out = {}
    for name, n, shape, kind in (("node_ids", ns, (ns,), np.int64), ("facets", nf * nv, (nf, nv), np.int64),
                                 ("body", nf, (nf,), np.int64), ("mass", ns, (ns,), np.float64),
                                 ("free", ns * dim, (ns, dim), np.float64), ("x", ns * dim, (ns, dim), np.float64),
                                 ("v", ns * dim, (ns, dim), np.float64)):
        out[name] = buf[pos:pos + n].astype(kind).reshape(shape)
        pos += n
    if pos < len(buf):  # particles
        out["smoothing_length"] = float(buf[pos])
        out["volume"] = buf[pos + 1: pos + 1 + ns].copy()
    return out


def send_state(adapter, comm, ic, extra: list) -> None:
    """A foreground's state after its step (TAG_STATE, collective): x^{n+1}, v^{n+1/2} of its surface
    nodes on the surface the coupler's operators were built on, then ``extra`` (substeps: their mean
    velocity and the ramp's work), then the particles' volumes (a foreground with volumes()), then a
    flag: 1 when the surface changed in this step (eroded elements), the new one following as
    TAG_SURFACE (orchestrator/coupling/embedded.py take_state reads it in this order)."""
    renew = getattr(adapter, "renew_surface", None)
    volumes = getattr(adapter, "volumes", None)
    state = np.concatenate([adapter.positions().ravel(), adapter.velocities().ravel(), *extra,
                            volumes() if volumes else [], [0.0]])
    changed = bool(renew and renew())
    state[-1] = float(changed)
    if comm.rank == 0:
        P.send(ic, state, 0, P.TAG_STATE)
    if changed:
        buf = pack_surface(adapter)
        if comm.rank == 0:
            P.send(ic, buf, 0, P.TAG_SURFACE)


def _substepped_step(adapter, comm, ic, dt: float, m: int, step: int, time: float, with_diagnostics: bool,
                     answer) -> float:
    """A foreground's coupled step in m substeps (orchestrator/coupling/multirate.py): the predictor
    pass under the coupler's predicted force ramp (TAG_PREDICT: [rate, slope] per surface node), its
    mean surface velocity to the coupler, then passes from the same start under the ramps the coupler
    sends (TAG_IMPULSE, a last element 1) until it accepts one (a last element 0); then the accepted
    pass's state: x^{n+1}, v^{n+1/2} (the last substep's), the substeps' mean velocity, the ramp's
    work, the surface flag.  Returns the seconds of its own work (its waits for the coupler excluded)."""
    from adapters.substeps import substeps

    rank = comm.rank
    t0 = _time.perf_counter()
    snap = adapter.snapshot()
    v0 = adapter.velocities()
    h_prev = adapter.substep_h_prev()   # (substeps.py: where its kicks sample the force ramp)
    shape, n = v0.shape, v0.size

    def one(h, t_k, imp):
        adapter.predict(h, step, t_k)
        adapter.correct(imp)

    work = _time.perf_counter() - t0
    ramp = P.share(comm, P.recv(ic, 0, P.TAG_PREDICT) if rank == 0 else None)
    first = True
    while True:   # a pass under the ramp; the coupler answers with the next pass's, or accepts
        t0 = _time.perf_counter()
        if not first:
            adapter.restore(snap)
        first = False
        v_mean, w, _ = substeps(one, adapter.velocities, m, dt, time, ramp[:n].reshape(shape),
                                ramp[n: 2 * n].reshape(shape), v0, h_prev)
        if rank == 0:
            P.send(ic, v_mean, 0, P.TAG_VSTAR)
        work += _time.perf_counter() - t0
        msg = P.share(comm, P.recv(ic, 0, P.TAG_IMPULSE) if rank == 0 else None)
        if msg[-1] == 0.0:   # accepted: this pass is the step
            break
        ramp = msg[:-1]
    t0 = _time.perf_counter()
    send_state(adapter, comm, ic, [v_mean.ravel(), [w]])
    answer(with_diagnostics)
    return work + _time.perf_counter() - t0


def serve(adapter_cls, argv=None) -> None:
    args = parse_args(argv)
    out = Path(args.out)
    place = P.join(args.role, args.roles.split(","))
    rank = place.comm.rank
    P.install_fault_handler(out, args.role, rank)
    P.register_process(out, args.role, rank)
    case = case_file.read(args.case, args.case_sha256)
    adapter = adapter_cls(place.comm, case, out)
    ic = place.inter[P.COUPLER]
    side = coupling_side(args.role) if case.get("coupling") else None
    comm = place.comm
    if side == "background":  # the bodies' initial geometry in the grid, before the initial state
        adapter.bodies = adapter.unpack_geometry(P.share(comm, P.recv(ic, 0, P.TAG_GEOMETRY) if rank == 0 else None))
    adapter.setup()
    probes = probes_for(case.get("probes"), args.role, comm)
    if probes:  # the probes' sets, from the initial positions (before a restart moves them)
        probes.start(adapter, args.role)
    if args.restart:
        adapter.restart(restart_file(Path(args.restart), args.role))
    if side == "foreground":  # the surface (fixed), its positions and velocities now
        buf = pack_surface(adapter)
        if rank == 0:
            P.send(ic, buf, 0, P.TAG_SURFACE)
    names = adapter.diagnostic_names() + probes.names
    reply = np.zeros(P.REPLY_HEAD + len(names))

    def answer(with_diagnostics: bool) -> None:
        dt = adapter.stable_dt()
        diag = adapter.diagnostics() if with_diagnostics else None
        if with_diagnostics and probes:
            diag.update(probes.values_of(adapter))
        if rank == 0:
            reply[0] = 0.0
            reply[1] = dt
            if diag is not None:
                reply[P.REPLY_HEAD:] = [diag[n] for n in names]
            ic.Send(reply, dest=0, tag=7)

    stable = adapter.stable_dt()   # (collective)
    adapter.describe()             # (collective where a solver sums over its ranks)
    if rank == 0:  # once, at start-up: the names of the diagnostics, whether the solver steps by
        # central differences, whether it can take a coupled step in substeps and its stable step
        # (whether substeps pay: orchestrator/coupling/multirate.py; pickled, not a hot path)
        ic.send((names, adapter.central_difference(),
                 adapter.substep_cost() if side == "foreground" and adapter.can_substep() else 0.0, stable,
                 adapter.describe()), dest=0, tag=6)
    answer(True)
    cmd = np.empty(P.CMD_LEN)
    work_s = 0.0  # this rank's time in the steps' own work (the waits for the coupler excluded)
    while True:
        P.wait(ic.Ibcast(cmd, root=0))  # not a spinning Bcast: the coupler may work a while (solve, output)
        c, dt, step, time, index = cmd[0], cmd[1], int(cmd[2]), cmd[3], int(cmd[4])
        t0 = _time.perf_counter()
        substeps = int(cmd[6])
        if c == P.CMD_STEP and side == "foreground" and substeps > 1:
            work_s += _substepped_step(adapter, comm, ic, dt, substeps, step, time, bool(cmd[5]), answer)
        elif c == P.CMD_STEP and side == "foreground":
            adapter.predict(dt, step, time)
            v = adapter.interface()["v"]
            if rank == 0:
                P.send(ic, v, 0, P.TAG_VSTAR)
            work_s += _time.perf_counter() - t0
            imp = P.share(comm, P.recv(ic, 0, P.TAG_IMPULSE) if rank == 0 else None)
            t0 = _time.perf_counter()
            adapter.correct(imp.reshape(v.shape))
            send_state(adapter, comm, ic, [])
            adapter.remap(None)
            answer(bool(cmd[5]))
            work_s += _time.perf_counter() - t0
        elif c == P.CMD_STEP and side == "background":
            adapter.predict(dt, step, time)
            buf = adapter.interface()
            if rank == 0:
                P.send(ic, buf, 0, P.TAG_INTERFACE)
            work_s += _time.perf_counter() - t0
            corr = P.share(comm, P.recv(ic, 0, P.TAG_CORRECT) if rank == 0 else None)
            t0 = _time.perf_counter()
            adapter.correct(adapter.unpack_correction(corr))
            work_s += _time.perf_counter() - t0
            geom = P.share(comm, P.recv(ic, 0, P.TAG_GEOMETRY) if rank == 0 else None)
            t0 = _time.perf_counter()
            adapter.remap(adapter.unpack_geometry(geom))
            answer(bool(cmd[5]))
            work_s += _time.perf_counter() - t0
        elif c == P.CMD_STEP:
            adapter.predict(dt, step, time)
            adapter.correct(None)
            adapter.remap(None)
            answer(bool(cmd[5]))
            work_s += _time.perf_counter() - t0
        elif c == P.CMD_WRITE:
            adapter.write(index, step, time)
            answer(False)
        elif c == P.CMD_LIMITER:   # what sets the stable step (a progress line, a message)
            lim = adapter.step_limiter()
            if rank == 0:
                ic.send(lim, dest=0, tag=P.TAG_LIMITER)
            answer(False)
        elif c == P.CMD_CHECKPOINT:
            adapter.checkpoint(out / "checkpoints" / f"step_{step:08d}" / f"{args.role}.h5")
            answer(False)
        elif c == P.CMD_STOP:
            answer(True)
            if rank == 0:  # where this group's time went (summary.json's solver_time_s)
                P.send(ic, np.array([work_s, float(getattr(adapter, "engine_s", np.nan))]), 0, P.TAG_TIMING)
            break
    adapter.close()
    # a clean exit: the launcher must not take this process's end for a failure
    pidfile = P.run_dir(out) / "pids" / str(os.getpid())
    pidfile.unlink(missing_ok=True)
