"""Map quality for the annotation backend: lint, proposal-to-final diffs and annotator figures (pure logic)."""

from app.backend.quality.diff import DiffConfig, ProposalDiff, chamfer_distance, match_vertices, proposal_diff
from app.backend.quality.figures import AnnotatorFigures, ReviewEvent, annotator_figures
from app.backend.quality.lint import (
    ElementView,
    LintConfig,
    LintFinding,
    LintWork,
    SiteLint,
    find_bad_crosswalks,
    find_broken_boundaries,
    find_crossing_dividers,
    find_dangling_divider_ends,
    find_divider_spacing,
    find_self_intersections,
    lint,
)

__all__ = [
    "AnnotatorFigures",
    "DiffConfig",
    "ElementView",
    "LintConfig",
    "LintFinding",
    "LintWork",
    "ProposalDiff",
    "ReviewEvent",
    "SiteLint",
    "annotator_figures",
    "chamfer_distance",
    "find_bad_crosswalks",
    "find_broken_boundaries",
    "find_crossing_dividers",
    "find_dangling_divider_ends",
    "find_divider_spacing",
    "find_self_intersections",
    "lint",
    "match_vertices",
    "proposal_diff",
]
