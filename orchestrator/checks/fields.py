"""What the checks read from a run's output: the last step, zone and particle profiles along an
axis (station means), cell centroids, the bodies' meshes, and the crossings and plateaus of a 1-D
profile.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np



def body_meshes(case: dict):
    """The Lagrangian bodies' meshes (case order) and each body's first node in the solver's
    concatenated numbering (the output's), with the total last: (meshes, first (n_bodies + 1,))."""
    from solvers.lagrange.mesh import body_mesh

    meshes = [body_mesh(b, case["run"]["dimension"]) for b in case["lagrange"]["bodies"]]
    return meshes, np.cumsum([0] + [m.num_points for m in meshes])


def cell_centroids(out: Path, role: str, index: int):
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, role)
    points, point_data, cell_data = output.read_step(out, role, index)
    return points[cells].mean(axis=1), points, point_data, cell_data


def station_means(key, fields: dict):
    """(the distinct station keys, ascending; {name: the mean of the field over each station})."""
    keys, inv = np.unique(key, return_inverse=True)
    count = np.bincount(inv)
    return keys, {name: np.bincount(inv, weights=a) / count for name, a in fields.items()}


def zone_stations(out: Path, role: str, index: int, axis: int):
    """1-D profile along `axis` of a run on a grid: zone fields averaged over each station."""
    from orchestrator import output

    cells, _ = output.read_mesh_file(out, role)
    points, pd, cd = output.read_step(out, role, index)
    centre = points[cells].mean(axis=1)[:, axis]
    fields = {"rho": cd["density"], "p": cd["pressure"], "u": pd["velocity"][cells].mean(axis=1)[:, axis]}
    if "specific_internal_energy" in cd:
        fields["e"] = cd["specific_internal_energy"]
    # several materials: volume fraction profiles
    fields.update({name: a for name, a in cd.items() if name.startswith("volume_fraction_")})
    xs, prof = station_means(np.round(centre, 12), fields)
    return {"x": xs, **prof}


def particle_stations(out: Path, role: str, index: int, axis: int, width: float):
    """1-D profile along `axis` of particles (a point cloud): density, pressure and velocity averaged
    over the particles of each station of `width` (m), stations without particles left out."""
    from orchestrator import output

    points, pd, _ = output.read_step(out, role, index)
    xa = points[:, axis]
    ks, prof = station_means(np.floor((xa - xa.min()) / width).astype(np.int64),
                              {"rho": pd["density"], "p": pd["pressure"], "u": pd["velocity"][:, axis]})
    return {"x": xa.min() + (ks + 0.5) * width, **prof}


def profile(case: dict, out: Path, role: str, index: int, axis: int):
    """The 1-D profile of a run along `axis`: grid zones (ALE) or particle stations one lattice spacing
    wide (SPH), by the kind of output the role writes."""
    from orchestrator import output

    _, cell_type = output.read_mesh_file(out, role)
    if cell_type == "vertex":
        return particle_stations(out, role, index, axis, case[role]["spacing"])
    return zone_stations(out, role, index, axis)


def last_step(out: Path, role: str):
    from orchestrator import output

    return output.read_steps(out, role)[-1]


def crossings(x, a, level):
    """(k, positions): the segments [x[k], x[k+1]] where the profile a crosses `level` (strictly,
    sign change) and the crossing positions by linear interpolation."""
    sgn = np.sign(a - level)
    k = np.flatnonzero(sgn[:-1] * sgn[1:] < 0)
    return k, x[k] + (level - a[k]) * (x[k + 1] - x[k]) / (a[k + 1] - a[k])


def plateau(x, a, lo, hi, margin, stat="mean"):
    sel = (x > lo + margin) & (x < hi - margin)
    if not sel.any():
        return float("nan")
    return float(np.median(a[sel]) if stat == "median" else a[sel].mean())
