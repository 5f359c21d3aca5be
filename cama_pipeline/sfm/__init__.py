"""Odometry-guided SfM (paper: OGI, rigid prior, iterative BA, parallel reconstruction).

The core is `guided.reconstruct_views(views, database, image_dir, SfmConfig)`: a known-pose model of the
views from WIGO poses and calibration (`model`), triangulation of every verified match (`triangulate`),
then one BA or Algorithm 1 (`iterative`), plain or rigid (`bundle`), with odometry priors (`priors`).
Per-clip execution, merging and the `cama sfm` stage build on it.
"""
