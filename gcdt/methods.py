"""The methods results compare, by name: each offline method is a trainer method (`dt` or `bc`)
plus a goal conditioning. Their one mapping: the grid trains by it, a trained policy is named
by it. `tqc`, the online baseline, is none of them."""

from __future__ import annotations

#: Method name -> (trainer method, goal conditioning).
OFFLINE_METHODS = {
    "gcdt": ("dt", "desired+achieved"),
    "dt": ("dt", "none"),
    "dt-desired": ("dt", "desired"),
    "bc": ("bc", "desired+achieved"),
}


def method_label(method: str, goal_conditioning: str) -> str:
    """How results name a trained model: its `OFFLINE_METHODS` name, else its trainer method's
    (BC is `bc` whatever its states hold)."""
    names = {trained: name for name, trained in OFFLINE_METHODS.items()}
    return names.get((method, goal_conditioning), method)
