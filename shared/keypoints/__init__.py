"""Body keypoints as the paper's 12 posture features.

3D positions of named body points (a skeleton tracker's, motion capture's) fitted with the human model
(fit.py); skeleton layouts (layouts.py); keypoint libraries, one CSV per class (library.py).
"""

from .fit import POINT_NAMES, REQUIRED, FitConfig, FitResult, KeypointFit, initial_guess

__all__ = ["POINT_NAMES", "REQUIRED", "FitConfig", "FitResult", "KeypointFit", "initial_guess"]
