"""Perception: camera images to a scene the tutor can trust (the paper's
VLM cascade, §3.2 and Appendix C).  See docs/perception.md."""

from __future__ import annotations

from virf.perception.catalogue import Catalogue, Match
from virf.perception.fuse import DEFAULT_THRESHOLD, Perception
from virf.perception.graph import SceneGraph
from virf.perception.pipeline import perceive

__all__ = ["DEFAULT_THRESHOLD", "Catalogue", "Match", "Perception", "SceneGraph", "perceive"]
