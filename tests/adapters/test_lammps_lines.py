"""The allow-list of LAMMPS lines a case may add (adapters/lammps_lines.py): every way to run a
command, load code, read or write a file or take the time loop is refused with its reason; the
lines the SPH cases need pass.  (Through the command line, with exit 2 and nothing launched:
tests/orchestrator/test_bad_inputs.py.)"""
from __future__ import annotations

import pytest

from adapters.lammps_lines import LammpsLineError, check_line

FORBIDDEN = [
    # (line, fragment of the reason)
    ("shell rm -rf x", "command 'shell'"),
    ("python f here x", "command 'python'"),
    ("include more.in", "command 'include'"),
    ("write_data out.data", "command 'write_data'"),
    ("write_restart out.restart", "command 'write_restart'"),
    ("write_dump all atom d.txt", "command 'write_dump'"),
    ("write_coeff c.txt", "command 'write_coeff'"),
    ("dump d all atom 10 d.txt", "command 'dump'"),
    ("log run.log", "command 'log'"),
    ("print hello", "command 'print'"),
    ("plugin load evil.so", "command 'plugin'"),
    ("read_data other.data", "command 'read_data'"),
    ("read_dump d.txt 0 x y z", "command 'read_dump'"),
    ("run 1000", "command 'run'"),
    ("rerun d.txt dump x y z", "command 'rerun'"),
    ("timestep 1.0", "command 'timestep'"),
    ("jump SELF loop", "command 'jump'"),
    ("label loop", "command 'label'"),
    ("clear", "command 'clear'"),
    ("quit", "command 'quit'"),
    ("restart 100 r.bin", "command 'restart'"),
    ("create_atoms 1 random 10 1 NULL", "command 'create_atoms'"),
    ("delete_atoms group all", "command 'delete_atoms'"),
    ("fix p all print 10 hello file out.txt", "keyword 'file'"),
    ("fix p all print 10 hello", "fix style 'print'"),
    ("fix a all ave/time 1 1 1 c_t", "fix style 'ave/time'"),
    ("fix a all python/invoke 1 end_of_step f", "fix style 'python/invoke'"),
    ("fix e all external pf/callback 1 1", "fix style 'external'"),
    ("fix s all halt 10 v_x > 1 error hard", "fix style 'halt'"),
    ("compute c all python f", "compute style 'python'"),
    ("variable v python f", "variable style 'python'"),
    ("variable v file names.txt", "keyword 'file'"),
    ("variable v getenv HOME", "variable style 'getenv'"),
    ("variable v atomfile a.txt", "variable style 'atomfile'"),
    ("variable v equal ${x}", "substitution"),
    ("variable v equal $(step)", "substitution"),
    ("thermo_style custom step & ", "continuation"),
    ('region r block 0 1 0 1 0 1 "side in"', "quotes"),
    ("group g type 1\nshell ls", "one line"),
    ("thermo_modify line one screen yes", "keyword 'screen'"),
    ("unfix immerse_integrate", "belong to immerse"),
    ("fix immerse_gravity all setforce 0 0 0", "belong to immerse"),
    ("fix g all", "needs an ID, a group and a style"),
    # memory and distance bounds (issue 41: these passed and could take the machine's memory)
    ("neigh_modify page 2000000000 one 1000000000", "neigh_modify page = 2000000000 must be an integer from 1 to 10000000"),
    ("neigh_modify one 1000000000", "neigh_modify one = 1000000000 must be an integer from 1 to 100000"),
    ("neigh_modify one 5000 page 20000", "must be >= 10 x neigh_modify one (50000)"),
    ("neigh_modify one -1", "must be an integer from 1"),
    ("neigh_modify binsize 1e-9", "between a quarter of the smoothing length"),
    ("neigh_modify binsize nan", "must be a finite number"),
    ("comm_modify cutoff 1000000", "comm_modify cutoff = 1000000 must be >= 0 and <= the domain's extent (2 m)"),
    ("comm_modify mode single cutoff 1e300", "<= the domain's extent"),
    ("comm_modify cutoff inf", "must be a finite number"),
    ("neighbor 1e300 bin", "neighbor skin = 1e300 must be >= 0 and <= the domain's extent"),
    ("neighbor -1 bin", "neighbor skin = -1 must be >= 0"),
    ("atom_modify sort 100 1e-12", "sort binsize = 1e-12 must be 0"),
    ("neigh_modify page", "needs a value"),
]

ALLOWED = [
    "",
    "# a comment",
    "region lid block 0 1 0.9 1 INF INF",
    "group lid region lid",
    "fix push lid addforce 0.0 -1.0 0.0",
    "fix drag all viscous 0.1",
    "fix side all wall/reflect xlo EDGE",
    "compute rho all sph/rho/atom",
    "compute ke all ke",
    "variable f equal 2.0*step",
    "neigh_modify every 1 delay 0 check yes",
    "neigh_modify one 5000 page 100000 binsize 0.02",
    "neigh_modify page 100000 one 5000",
    "comm_modify vel yes cutoff 0.3",
    "neighbor 0.01 bin",
    "atom_modify sort 1000 0.05",
    "velocity lid set 0.0 -1.0 0.0",
    "set type 1 mass 2.0",
    "thermo 100",
]


@pytest.mark.parametrize("line, fragment", FORBIDDEN, ids=[f[0].split()[0] + "-" + str(i) for i, f in enumerate(FORBIDDEN)])
def test_forbidden_line_refused_with_its_reason(line, fragment):
    with pytest.raises(LammpsLineError) as ei:
        check_line(line, 2.0, 0.03)   # a domain 2 m across, h = 3 cm
    assert fragment in str(ei.value)
    assert "\n" not in str(ei.value)


@pytest.mark.parametrize("line", ALLOWED)
def test_allowed_line_passes(line):
    check_line(line, 2.0, 0.03)
    check_line(line)   # without the case's scales: the absolute limits only


def test_not_a_string_refused():
    with pytest.raises(LammpsLineError, match="must be a string"):
        check_line(["shell", "ls"])
