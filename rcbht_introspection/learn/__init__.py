"""Sub-task classifiers (SVM, online Mondrian forest), safe model files and evaluation."""
