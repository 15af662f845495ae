"""Peer baselines: published methods run beside the verifier on the same folds (docs/peers.md).

Tools around the core, never imported by the nodes or by taxonomy/, live/, learn/ or verify/
at import time; they need the `peers` extra (requirements-peers.txt: hmmlearn, aeon), which
`make setup` installs. Import the modules themselves (`peers.hmm`, `peers.minirocket`): this
package imports neither library.
"""
