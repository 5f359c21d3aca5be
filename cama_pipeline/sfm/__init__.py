"""Odometry-guided SfM: triangulation from WIGO poses, rigid (rig) BA, odometry priors and iterative BA
(`guided.reconstruct_views`), per-clip parallel reconstruction and merging on top of it."""
