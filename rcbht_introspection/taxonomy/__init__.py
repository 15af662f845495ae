"""The RCBHT taxonomy, pure NumPy: primitives -> motion compositions -> low-level behaviours."""

from typing import Literal

StreamProfile = Literal["reference", "causal", "live"]
"""reference: the words equal the batch engine's (whole-trial quantities are waited for);
causal: past samples only; live: causal, and every word final within finality_bound_s.
Here (not in stream.py) so the CLI lists it without the engine."""
