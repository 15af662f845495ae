"""The RCBHT taxonomy, pure NumPy: primitives -> motion compositions -> low-level behaviours."""

from typing import Literal

StreamProfile = Literal["reference", "causal"]
"""reference: the words equal the batch engine's (whole-trial quantities are waited for);
causal: past samples only. Here (not in stream.py) so the CLI lists it without the engine."""
