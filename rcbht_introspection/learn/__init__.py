"""Sub-task classifiers (SVM, online Mondrian forest), safe model files and evaluation."""

from typing import Literal, get_args

ClassifierKind = Literal["forest", "svm-forest", "svm", "svm-tuned", "mondrian"]
"""Classifier names; here (not in models.py) so the CLI lists them without importing scikit-learn."""
CLASSIFIERS: tuple[str, ...] = get_args(ClassifierKind)
DEFAULT_CLASSIFIER: ClassifierKind = "forest"
"""What `rcbht train` and `rcbht evaluate` fit: a random forest names finished sub-tasks, and its
running heads are the SVM + forest vote (running_classifier_of)."""
CLASSIFIER_HELP = (
    "forest (default): a random forest names finished sub-tasks, the SVM + forest vote running "
    "windows; svm-forest: the vote for both; svm, svm-tuned: the paper's; mondrian: our online "
    "forest, which the running node can be taught"
)


def running_classifier_of(classifier: ClassifierKind) -> ClassifierKind:
    """The classifier of a model's running heads (live and window): the SVM + forest vote beside
    a forest, which reads a sub-task's first quarter better; else the model's own."""
    return "svm-forest" if classifier == "forest" else classifier


WordSource = Literal["auto", "golden", "engine"]
"""Where sub-task words come from: golden label files if present (auto), only golden, or the
batch engine."""
WORD_SOURCES: tuple[str, ...] = get_args(WordSource)
