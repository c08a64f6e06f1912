"""Tautges et al. 2008, "Reconstruction of human motions using few sensors": the multilinear
motion model (``tautges2008``). Its PCA baseline is :mod:`imuloco.methods.pca_local`."""

from imuloco.methods.tautges2008.method import Tautges2008

__all__ = ["Tautges2008"]
