"""Paper 000's cascaded navigation + control filters for the tractor (issue 7).

Two six-state filters in cascade (paper 000, section 6):

- the *navigation* filter ``X1 = [E, N, r_b, psi, g_b, psi_b]`` (eq. 15-17), driven by the
  Doppler radar speed and the FOG yaw rate as inputs, updated by RTK GPS East/North and the
  multi-antenna heading (``Y1``; no update while GPS is unavailable, the paper's ``C1 = 0``);
- the *control* filter ``X2 = [psi_dot, psi_ddot, V_x, delta, delta_dot, delta_b]`` (eq.
  18-19), driven by the steering command, updated by the yaw rate and speed *corrected with
  the navigation filter's bias estimates* and the steer potentiometer (``Y2``).

Filters (``filters.<name>`` in params.yaml): ``cascaded_ekf`` (both filters EKF, Euler time
update, eq. 21-23), ``cascaded_ukf`` (both UKF, eq. 24-27, alpha 1e-3, beta 2, kappa 0) and
``cascaded_hybrid`` (the paper's future-work hybrid; see ``filters``). Their sections are
typed in ``config``; ``estimation.config`` holds them with every other filter's.

Layout: ``model`` (the physics as pure functions: f, F, h, H, Q, R), ``numerics`` (small
generic pieces the INS kernels do not provide for a six-state filter), ``filters``
(compiled predict/update of the three estimators), ``cascade`` (one sample of the cascade and
the compiled replay loop), ``reference`` (the same model through filterpy), ``engine`` (run
set-up, run state and the compiled stepper), ``backends`` (a stepper of either backend by
name, and the open-loop replay), ``inputs``/``outputs``/``metrics``/``run`` (tables
in, run directory out), ``closed_loop`` (the LQR steering the simulator from the estimates)
and ``experiments``/``figures`` (the paper's scenario, Monte Carlo, outages).
"""
