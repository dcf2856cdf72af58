"""Solver adapters: each solver group speaks the same small coupling contract (see adapters.base)
to the coupler over an MPI intercommunicator. Adapters register themselves by role name."""
