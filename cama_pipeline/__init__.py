"""CAMA Studio reconstruction pipeline: from nuScenes-layout driving data to BEV rasters."""
