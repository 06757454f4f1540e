"""The domain-free helpers every package shares, the bottom layer: name -> implementation
tables and near-miss suggestions (``registry``), the one atomic file write (``files``), the one
field checker (``fields``), the one ``ergo: error:`` line (``cli_errors``). It knows no arm,
camera, simulator or learner and imports nothing of the project
(tests/system/test_layering.py)."""
