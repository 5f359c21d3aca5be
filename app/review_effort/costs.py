"""What each editor action costs a person, from the keystroke-level model (Card, Moran & Newell, 1980).

KLM operators: M (mentally prepare / decide) 1.35 s, P (point with the mouse) 1.1 s, B (press or release a
button) 0.1 s, K (a keystroke, average skilled typist) 0.28 s. Editor actions are sums of them; the defaults
are stated per action so a reader can check them against the editor's shortcuts (accept = one key, etc.).
"""

from dataclasses import dataclass

M_S, P_S, B_S, K_S = 1.35, 1.1, 0.1, 0.28


@dataclass(frozen=True)
class ActionCosts:
    """Seconds per action in the editor."""

    inspect_s: float = M_S + K_S
    """Look at a leased element and decide (M), having pressed "next" (K)."""
    verdict_s: float = K_S
    """Accept / fixed / reject: one shortcut."""
    move_vertex_s: float = P_S + B_S + P_S + B_S
    """Drag one vertex: point, press, point to the target, release."""
    add_vertex_s: float = P_S + 2 * B_S
    """Insert a vertex on a segment (point, click) or extend an end."""
    delete_vertex_s: float = P_S + 2 * B_S + K_S
    """Point at a vertex, select it, press delete."""
    relabel_s: float = K_S
    """Change the class: one number key."""
    draw_start_s: float = M_S + K_S
    """Find where a new element goes and pick the drawing tool."""
    draw_vertex_s: float = P_S + 2 * B_S
    """Click one vertex of a new polyline."""
    draw_finish_s: float = K_S
    """Finish the polyline (Enter / double click)."""
    simplify_s: float = K_S
    """Simplify the selected polyline: one key."""
    move_element_s: float = K_S + P_S + B_S + P_S + B_S
    """Move the selected element whole (Ctrl/Cmd-drag): hold the key, point at it, press, drag, release."""
    merge_s: float = P_S + B_S + K_S + K_S
    """Shift-click a second polyline to add it to the selection, press the merge key."""
    split_s: float = P_S + K_S
    """Split the selected polyline at the vertex under the pointer (the editor's K): point at it, press the key."""
    scan_per_100m_s: float = 10.0
    """Looking over 100 m of road for elements nobody proposed: spent in both workflows."""

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if value < 0:
                raise ValueError(f"ActionCosts.{name}: must be >= 0 seconds, got {value}")
