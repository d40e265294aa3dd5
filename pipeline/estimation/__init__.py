"""Estimation core: strapdown INS with loosely and tightly coupled GNSS, EKF and UKF, NHC."""
