"""Image masks for data sets that have none: semantic ids and lane instances predicted by the project's own
segmentation network, or imported from another network's label set (Cityscapes, Mapillary Vistas)."""
