"""Realism checks of generated images: do SIFT features match on the road, as SfM needs them to?"""

import cv2
import numpy as np

from cama_pipeline.semantics import Semantic

ROAD_CLASSES = (Semantic.ROAD, Semantic.CURB, Semantic.LANE_MARKING, Semantic.CROSSWALK)


def road_sift_inliers(
    rgb_a: np.ndarray, rgb_b: np.ndarray, semantic_a: np.ndarray, ratio: float = 0.8, ransac_px: float = 1.0
) -> int:
    """SIFT matches between two images that pass the ratio test and a fundamental-matrix RANSAC and lie on
    road-surface pixels of the first image."""
    sift = cv2.SIFT.create()
    kp_a, des_a = sift.detectAndCompute(cv2.cvtColor(rgb_a, cv2.COLOR_RGB2GRAY), None)
    kp_b, des_b = sift.detectAndCompute(cv2.cvtColor(rgb_b, cv2.COLOR_RGB2GRAY), None)
    if des_a is None or des_b is None or len(kp_a) < 8 or len(kp_b) < 8:
        return 0
    good = [m for m, n in cv2.BFMatcher().knnMatch(des_a, des_b, k=2) if m.distance < ratio * n.distance]
    if len(good) < 8:
        return 0
    pa = np.array([kp_a[m.queryIdx].pt for m in good], dtype=np.float32)
    pb = np.array([kp_b[m.trainIdx].pt for m in good], dtype=np.float32)
    _, inlier = cv2.findFundamentalMat(pa, pb, cv2.FM_RANSAC, ransac_px, 0.999)
    if inlier is None:
        return 0
    on_road = np.isin(semantic_a[pa[:, 1].astype(int), pa[:, 0].astype(int)], [int(c) for c in ROAD_CLASSES])
    return int((inlier.ravel().astype(bool) & on_road).sum())
