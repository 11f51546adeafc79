"""Point-sampled surfaces: the surfel data model and operators on it (thesis ch. 3)."""

from unmesh.surfels.cloud import DEFAULT_COLOR, SurfelCloud, tangent_frame

__all__ = ["DEFAULT_COLOR", "SurfelCloud", "tangent_frame"]
