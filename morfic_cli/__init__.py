"""morfic: morphology-conditioned critics for zero-shot quadruped transfer.

Importing this package must stay cheap: it must not import torch or mujoco.
"""

__version__ = "0.1.0"
