"""More of the same: new leaves of a species by structural layering (Assa & Cohen-Or)."""

# registration (l17-tps)
from .registration import Registration, keypoints, register

__all__ = [
    # registration (l17-tps)
    "Registration",
    "keypoints",
    "register",
]
