"""Navigation physics shared by the synthesizers and the estimators: WGS-84 earth model,
attitude conventions and the strapdown mechanization (numba-compiled)."""
