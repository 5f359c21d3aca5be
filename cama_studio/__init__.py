"""The composition root: the `cama` command line (`cli`), `cama run` (`run_command`) and the whole-run runner
(`pipeline`). It sits above every package it composes (the pipeline stages, annotations, models, the backend and
the viewer); nothing imports it but entry points, tests and benches (the layer order is in README, "Layers")."""
