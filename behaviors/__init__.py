"""The IvP helm: decision domain, objective functions, solver, .bhv files, modes and behaviours."""
