"""The population benchmark the closed loop is judged on (issue 63): cases from an
independent forward model (tests/population_model.py), run through ``vibid identify``,
scored for recall, false additions, coverage, honesty and time (``run.py``)."""
