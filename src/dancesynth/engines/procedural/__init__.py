"""Procedural upper-body animation from music (Loi & Li, APSIPA ASC 2009).

Read in the paper's order: ``segment`` (§IV, Fig. 2, eq. 1-5), ``keyframes``
(§V.B, eq. 6-8, Fig. 8), ``bezier`` (§V.D, Fig. 5-6), ``speed`` (§V.E, Fig. 7),
``arm_ik`` (the analytic arm IK), ``body`` (§V.G), ``engine`` (Fig. 1 end to end);
``config`` holds every parameter and the styles.
"""

from .config import STYLES, ProceduralConfig, load_config, make_config, parse_params
from .engine import conduct_notes, default_skeleton

__all__ = ["STYLES", "ProceduralConfig", "conduct_notes", "default_skeleton", "load_config", "make_config",
           "parse_params"]
