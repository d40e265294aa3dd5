"""What every filter family shares: the run contract and its writer (``contract``), the outage
windows and their metrics (``windows``), NEES and NIS (``consistency``), what a run reads of
the canonical tables (``tables``), parameter checks (``checks``), and the compiled pieces of
every family's filters: linear algebra (``linalg``), the unscented transform (``unscented``),
gating and recording (``gating``) into the run log (``runlog``).

Nothing here imports a family (``estimation.ins``, ``estimation.vehicle``,
``estimation.cascaded``); they import it.
"""
