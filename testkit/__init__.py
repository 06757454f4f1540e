"""What tests, bench/ and experiments/ share and the product never runs: the scripted owner on a
served stand-in and the reader of its hidden truth, the fault soak, synthetic camera views,
untrained goal-space models, the inverse-model diagnosis. Not installed (pyproject's package
list leaves it out); importable from the repository's root (pytest's ``pythonpath``, and the
scripts put the root on ``sys.path``). No product package imports it
(tests/system/test_layering.py)."""
