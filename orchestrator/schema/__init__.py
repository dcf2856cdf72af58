"""The case file's schema: the core tables and the assembled JSON Schema (case.py), the building
blocks and annotation keywords (parts.py), the cross-field rules and the one-line refusals
(rules.py), and the registry of the solvers' table fragments (registry.py), each fragment a module
of its own (ale.py, lagrange.py, sph.py, coupling.py, contact.py, probes.py)."""
