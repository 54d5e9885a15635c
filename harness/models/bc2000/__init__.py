"""Compiled kernels of the Bourguignon & Cani (2000) program (generated: see codegen.py)."""
