"""VIRF: the Verifiable Iterative Refinement Framework.

Data flows one way: scene -> kb (ABox) -> sim (step) -> reasoning -> verify
(diagnosis) -> feedback -> planner.  The public entry points are re-exported
from :mod:`virf.api`.
"""

__version__ = "0.1.0"
