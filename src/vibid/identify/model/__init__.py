"""The forward model: discretisation, model terms, and the full, modal and reduced solvers."""
