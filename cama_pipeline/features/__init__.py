"""Local features and matching: masked SIFT (pycolmap) into a COLMAP database, matched on the selected pairs."""
