"""Case-file texts several test modules build their cases from."""

# a 3-D run with a linear-elastic steel and the head of its first body, "bar" (its mesh, velocities
# and anything after it follow)
STEEL_BAR_HEAD = """\
[run]
dimension = 3
end_time = 1e-5

[materials.steel]
model = "linear_elastic"
density = 8000.0
youngs_modulus = 200e9
poisson_ratio = 0.3

[[lagrange.bodies]]
name = "bar"
material = "steel"
"""

# Sod's shock tube on a 100 x 1 zone 2-D background (no [check])
SOD_2D = """\
[run]
dimension = 2
end_time = 0.2

[ale]
grid = { lower = [0.0, 0.0], upper = [1.0, 0.01], cells = [100, 1] }
materials.gas = { eos = "ideal_gas", gamma = 1.4 }
regions = [
  { material = "gas", density = 1.0, pressure = 1.0 },
  { material = "gas", region = "x > 0.5", density = 0.125, pressure = 0.1 },
]
"""
