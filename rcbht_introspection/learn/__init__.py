"""Sub-task classifiers (SVM, online Mondrian forest), safe model files and evaluation."""

from typing import Literal, get_args

ClassifierKind = Literal["svm-forest", "svm", "svm-tuned", "mondrian"]
"""Classifier names; here (not in models.py) so the CLI lists them without importing scikit-learn."""
CLASSIFIERS: tuple[str, ...] = get_args(ClassifierKind)
WordSource = Literal["auto", "golden", "engine"]
"""Where sub-task words come from: golden label files if present (auto), only golden, or the
batch engine."""
WORD_SOURCES: tuple[str, ...] = get_args(WordSource)
