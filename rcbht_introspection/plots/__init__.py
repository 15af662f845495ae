"""Figures (matplotlib): kept out of the pure core so taxonomy, grammar and learn never import it."""
