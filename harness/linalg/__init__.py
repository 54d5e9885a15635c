"""Sparse linear algebra shared by the reference, the models' statics and the optimisers."""
