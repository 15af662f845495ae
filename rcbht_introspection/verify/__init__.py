"""Verification: is the running sub-task going wrong? Causal failure detection (novelty against
successful trials, belief/phase mismatch) and failure characterisation (class, deviation
direction), pure Python (NumPy, scikit-learn); the verifier node and `rcbht verify-eval` use it."""
