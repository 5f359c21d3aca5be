"""3D review in viser: the road mesh, lifted vectors by class and state, keyframe cameras and sparse points."""
