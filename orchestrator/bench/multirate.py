"""`immerse bench multirate`: time to solution against the step ratio, single-rate and multi-rate
(orchestrator/coupling/multirate.py), with the accuracy at each.

The scene: cases/embedded_piston_sod (a piston in a Sod tube, its exact Riemann answer the check's
references), the piston's stable step capped r times below the gas's (run.group_dt_max: r = 1 is the
case as shipped, its piston's step 0.6 of the gas's), each ratio run single-rate (every group at the
piston's step) and multi-rate (the gas at its own, the piston in substeps).  Per run: the wall time of
the time loop (summary.json's wall_time_s, start-up excluded), the coupling steps, the substeps per
coupling step, the check's relative errors and the interface's work; one run a point (the single-rate
runs at r = 64 take ~90 s each), the machine's noise is a few per cent.  Charted: wall time and
errors against r (multirate.png)."""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

from orchestrator.bench.coupling_studies import CASES, _figure, _replace, _run
from orchestrator.bench.registry import bench, machine

CASE = "embedded_piston_sod"
GAS_STEP = 5.5e-4   # s: about the piston's stable step in the shipped case (0.6 of the gas's)
METRICS = ("centre", "velocity", "p_left", "p_right")


def case_text(ratio: int, multi: bool) -> str:
    text = (CASES / CASE / "case.toml").read_text()
    add = f"multirate = {'true' if multi else 'false'}"
    if ratio > 1:
        add += f"\ngroup_dt_max = {{ lagrange = {GAS_STEP / ratio!r} }}"
    return _replace(text, "[run]\n", f"[run]\n{add}\n", CASE)


def measure(ratios) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in ratios:
            for multi in (False, True):
                got = _run(case_text(r, multi), Path(tmp) / f"r{r}_{int(multi)}")
                s = got["summary"]
                if got["rc"] not in (0, 1) or s is None:
                    raise RuntimeError(f"bench multirate: ratio {r}, multirate {multi}: {got['message']}")
                m = s["check"]["metrics"]
                rows.append({"ratio": r, "multirate": multi, "wall_s": s["wall_time_s"], "steps": s["steps"],
                             "substeps_mean": (s.get("multirate") or {}).get("lagrange", {}).get("per_step_mean", 1.0),
                             "errors": {k: m[k]["rel_error"] for k in METRICS},
                             "interface_work_j": s["final"]["coupling.interface_work"]})
    return rows


def results(rows) -> list[dict]:
    out = []
    for row in rows:
        mode = "multi-rate" if row["multirate"] else "single-rate"
        params = {"case": CASE, "ratio": row["ratio"], "mode": mode, "steps": row["steps"],
                  "substeps_per_step": row["substeps_mean"], "runs": 1}
        out.append({"name": f"{mode}_ratio_{row['ratio']}", "metric": "wall_time", "value": row["wall_s"],
                    "unit": "s", "params": params})
        for k, v in row["errors"].items():
            out.append({"name": f"{mode}_ratio_{row['ratio']}", "metric": f"{k}_rel_error", "value": v,
                        "unit": "1", "params": params})
        out.append({"name": f"{mode}_ratio_{row['ratio']}", "metric": "interface_work", "value": row["interface_work_j"],
                    "unit": "J", "params": params})
    for r in sorted({row["ratio"] for row in rows}):
        a, b = (next(x for x in rows if x["ratio"] == r and x["multirate"] == m) for m in (False, True))
        out.append({"name": f"speedup_ratio_{r}", "metric": "wall_time_single_over_multi",
                    "value": a["wall_s"] / b["wall_s"], "unit": "1", "params": {"case": CASE, "ratio": r}})
    return out


def draw(rows, path: Path) -> None:
    plt, fig, (ax1, ax2) = _figure(2)
    for multi, style in ((False, "o--"), (True, "s-")):
        sel = [r for r in rows if r["multirate"] == multi]
        label = "multi-rate" if multi else "single-rate"
        ax1.loglog([r["ratio"] for r in sel], [r["wall_s"] for r in sel], style, label=label)
        for k, c in zip(METRICS, ("tab:blue", "tab:orange", "tab:green", "tab:red")):
            ax2.loglog([r["ratio"] for r in sel], [max(r["errors"][k], 1e-12) for r in sel], style, color=c,
                       label=f"{k} ({label})")
    ax1.set(xlabel="piston's step below the gas's (ratio)", ylabel="wall time of the time loop (s)",
            title=f"{CASE}: time to solution")
    ax2.set(xlabel="piston's step below the gas's (ratio)", ylabel="relative error (check)",
            title="accuracy against the exact Riemann answer")
    ax1.legend()
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@bench("multirate")
def bench_multirate(out: Path, quick: bool = False) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = measure((1, 4, 16) if quick else (1, 2, 4, 8, 16, 32, 64))
    out.write_text(json.dumps({"results": results(rows), "rows": rows, "machine": machine()}, indent=2))
    draw(rows, out.parent / "multirate.png")
    return out
