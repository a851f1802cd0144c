"""Test campaigns: the paper's matrix of sessions (series x weights W x wire lengths l0 x repeats) from one YAML file
(:mod:`.spec`), run on the simulated rig or on hardware (:mod:`.runner`, the only module here that imports ROS),
analysed together (:mod:`.analyze`, :mod:`.figures`, :mod:`.report`), and the model calibrated on them
(:mod:`.calibrate`). Per-session analyses run in local processes or on a Dask cluster (:mod:`.parallel`)."""
