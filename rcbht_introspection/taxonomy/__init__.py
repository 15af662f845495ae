"""The RCBHT taxonomy, pure NumPy: primitives -> motion compositions -> low-level behaviours."""
