"""`immerse bench` writes the documented JSON (smoke run of the cheapest sweep; speed is never
asserted, but the Sod sweep's accuracy is: first-order convergence of the L1 density error)."""
import json

from tests.conftest import immerse


def test_bench_sod_quick(tmp_path):
    out = tmp_path / "bench-sod.json"
    r = immerse("bench", "sod", "--quick", "--out", out, timeout=300)
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert set(doc) == {"results", "machine"}
    res = doc["results"]
    assert [x["params"]["zones"] for x in res] == [100, 200, 400]
    assert all(x["metric"] == "l1_density_error" and x["unit"] == "" for x in res)
    errors = [x["value"] for x in res]
    assert errors[0] > errors[1] > errors[2]
    assert all(x["params"]["observed_order"] > 0.7 for x in res[1:])  # shocks: order ~1 expected


def test_bench_unknown_name():
    r = immerse("bench", "nonsense")
    assert r.returncode == 2 and "bench NAME = 'nonsense'" in r.stderr
