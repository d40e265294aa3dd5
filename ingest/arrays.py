"""The numpy array types of ingest's annotations, named once: ``F64``, ``I64`` ... (the dtype)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
I32 = npt.NDArray[np.int32]
I16 = npt.NDArray[np.int16]
U8 = npt.NDArray[np.uint8]
Bools = npt.NDArray[np.bool_]
