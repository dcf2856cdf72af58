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
