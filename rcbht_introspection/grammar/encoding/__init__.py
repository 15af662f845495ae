"""Feature encodings of sub-task samples, fitted on training data only and stored in the model.

One module per concern: `paper` and `compact` (the two encodings), `axes` (the compact features
of one arm/level/axis and `AxisMemo`, their incremental reuse for a running window),
`selection` (the compact encoding's feature selection), `labels` (shared label helpers),
`cache` (`SampleCache`, the per-sample memo an encoding owns) and `registry` (encodings by
name and from a model file's parameters). Nothing here is imported eagerly: `axes` stays free
of scikit-learn.
"""
