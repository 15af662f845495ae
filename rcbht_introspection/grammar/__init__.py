"""From words to sub-task samples: state split and encodings."""

from typing import Literal, get_args

Encoding = Literal["compact", "paper"]
"""Encoding names; here (not in encoding.py) so the CLI lists them without importing scikit-learn."""
ENCODINGS: tuple[str, ...] = get_args(Encoding)
