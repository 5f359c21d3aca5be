"""A scripted annotator that works through the backend's annotator queue, with a time cost per action."""
