"""Particle positions for the SPH group (solvers/particles.py): lattices in regions and LAMMPS data
files."""
from __future__ import annotations

import numpy as np
import pytest

from solvers.particles import DataFileError, lattice_points, points_in, read_data_positions

SPH_DATA = """LAMMPS data file (a water column)

3 atoms
1 atom types

0 1 xlo xhi
0 1 ylo yhi
-0.1 0.1 zlo zhi

Masses

1 0.001

Atoms # sph

3 1 1000.0 0.0 1.0 0.25 0.75 0.0
1 1 1000.0 0.0 1.0 0.25 0.25 0.0 0 0 0
2 1 1000.0 0.0 1.0 0.75 0.25 0.0

Velocities

1 0 0 0
"""


def test_data_file_positions_in_id_order():
    """The sph style's x y z (columns 6-8), image flags allowed, sorted by atom id; the next section
    ends the atoms."""
    x = read_data_positions(SPH_DATA, 2)
    assert np.array_equal(x, [[0.25, 0.25], [0.75, 0.25], [0.25, 0.75]])
    atomic = SPH_DATA.replace("Atoms # sph", "Atoms").replace(" 1000.0 0.0 1.0", "")
    assert np.array_equal(read_data_positions(atomic, 2), x)
    assert read_data_positions(atomic, 3).shape == (3, 3)


@pytest.mark.parametrize("text, fragment", [
    (SPH_DATA.replace("Atoms # sph", "Bonds"), "has no Atoms section"),
    (SPH_DATA.replace("Atoms # sph", "Atoms # ellipsoid"), "Atoms style 'ellipsoid'; allowed: atomic"),
    (SPH_DATA.replace("2 1 1000.0 0.0 1.0 0.75 0.25 0.0", "2 1 1000.0 0.75 0.25 0.0"),
     r"Atoms # sph section \(3 lines of at least 8 numbers.*with 6 columns"),
    (SPH_DATA.replace("0.75 0.25 0.0", "0.75 x 0.0"), "could not convert string 'x'"),
    (SPH_DATA.replace("3 atoms", "4 atoms"), "could not convert string 'Velocities'"),
    (SPH_DATA.replace("3 atoms", "2 Atoms"), "no 'N atoms' line in its header"),
    (SPH_DATA.replace("3 1 1000.0", "3.5 1 1000.0"), "atom id that is not a positive integer"),
    (SPH_DATA.replace("3 1 1000.0", "1 1 1000.0"), "repeats an atom id"),
    (SPH_DATA.replace("0.25 0.75 0.0", "0.25 0.75 0.5"), "2-D run needs z = 0"),
])
def test_a_bad_data_file_names_what_is_wrong(text, fragment):
    with pytest.raises(DataFileError, match=fragment):
        read_data_positions(text, 2)


def test_a_data_file_with_windows_line_ends_reads_the_same():
    assert np.array_equal(read_data_positions(SPH_DATA.replace("\n", "\r\n"), 2), read_data_positions(SPH_DATA, 2))
    atomic = SPH_DATA.replace("Atoms # sph", "Atoms").replace(" 1000.0 0.0 1.0", "")
    assert np.array_equal(read_data_positions(atomic.replace("\n", "\r\n"), 2), read_data_positions(SPH_DATA, 2))


def test_a_header_over_the_limit_is_refused_before_the_atoms_are_read():
    """A header declaring 1e9 atoms (the section after it not even numbers) is refused by its count,
    naming it and the limit: nothing of the section is parsed; the same file within the limit reads."""
    text = SPH_DATA.replace("3 atoms", "1000000000 atoms").replace("0.75 0.25 0.0", "x y z")
    with pytest.raises(DataFileError, match="declares 1000000000 atoms") as err:
        read_data_positions(text, 2, max_atoms=100)
    assert err.value.allowed == "at most 100 atoms"
    assert read_data_positions(SPH_DATA, 2, max_atoms=3).shape == (3, 2)


def test_points_in_a_region_match_its_lattice():
    """points_in with the box test is the lattice's own filter: a lattice's points all lie in its
    region (the sphere's, narrowed by where), and none of a shifted copy outside it does."""
    region = {"sphere": {"centre": [0.0, 0.0], "radius": 0.5}, "where": "x > 0"}
    x = lattice_points(region, 0.05, 2)
    assert points_in(region, x, 2).all() and len(x) > 0
    assert not points_in(region, x + [1.0, 0.0], 2).any()
