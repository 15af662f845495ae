"""Sub-task classifiers (SVM, online Mondrian forest), safe model files and evaluation."""

CLASSIFIERS: tuple[str, ...] = ("svm", "svm-tuned", "mondrian")
"""Classifier names; here (not in models.py) so the CLI lists them without importing scikit-learn."""
