"""Image pairs to match: sequential pairs within a clip and homography-guided spatial pairs (HSP) across clips."""
