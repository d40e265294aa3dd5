"""The outage and satellite-count experiments (issue 6) over the scenario engine.

``runs`` replays one filter under named scenarios (the run stage); ``montecarlo`` draws
outage placements with seeds and replays each window from the nominal run's state at its
start (the Monte Carlo stage); ``stats`` holds the paired intervals; ``tables`` reduces the
Monte Carlo windows to the per-satellite-count reduction table (paper 001, Table 1) and the
drift against outage length, with the comparison to the paper.
"""
