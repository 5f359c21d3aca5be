"""The element-mask VMA proposer: a BEV segmentation network whose masks are vectorised afterwards (HDMapNet-style).

`config` (model and training settings), `targets` (vectors rasterised into per-class masks), `net` (the U-Net),
`checkpoint` (versions with the data they saw), `train` (from generator sites and from corrections),
`propose` (site rasters -> class probabilities -> vectors with calibrated confidence).
"""
