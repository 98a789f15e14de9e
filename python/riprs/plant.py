"""The nonlinear rotary inverted pendulum (Furuta pendulum) driven by a DC motor.

Convention
----------
State ``x = [theta, theta_dot, alpha, alpha_dot]`` (the paper's order): arm angle (rad,
positive in the direction a positive voltage turns the motor), arm rate, pendulum angle
(rad, **0 = upright**, positive when the pendulum leans against positive arm rotation, the way an
upright pendulum falls when the arm accelerates positively), pendulum rate. Input: motor voltage
``u`` (V); outputs ``[theta, alpha]``. With this choice a positive voltage accelerates both
angles positively about upright, matching the all-positive ``B_d`` of the paper.

Model
-----
Both links are uniform rods pivoted at an end (``Jr``, ``Jp`` are centroidal inertias; the
parallel-axis terms are added), viscous friction on both joints, and the motor torque
``tau = kt (u - km theta_dot) / Rm``. See :class:`Plant` for the equations.

Presets
-------
:meth:`FurutaParams.qube_servo2`
    Quanser QUBE-Servo 2, published values (``qube2_rotpen_param.m`` of the rotary pendulum
    workbook): ``Rm = 8.4``, ``kt = km = 0.042``, ``mr = 0.095``, ``Lr = 0.085``,
    ``mp = 0.024``, ``Lp = 0.129``, ``Jr = mr Lr^2/12``, ``Jp = mp Lp^2/12``, ``Dr = 0.001``,
    ``Dp = 0.00005`` (other sources quote 10x the pendulum damping, which no swing-up within
    the arm's travel can overcome: see ``rip_core::plant``). Quanser's own model uses ``Jr``
    directly as the inertia about the motor axis and drops the ``Jp sin^2(alpha)`` term; riprs
    reads both inertias as centroidal.
:meth:`FurutaParams.paper`
    Fitted with :meth:`FurutaParams.fit` so that the upright linearisation, discretised at
    0.01 s, reproduces the paper's ``A_d`` and ``B_d`` to their printed precision (largest
    deviation from the recovered unrounded model: 0.07 of half a printed digit). A linear model
    fixes only six combinations of the parameters; ``Rm``, ``kt``, ``km``, ``mr``, ``mp`` and
    ``g`` are held at the QUBE-Servo 2 values and ``Lr``, ``Lp``, ``Jr``, ``Jp``, ``Dr``, ``Dp``
    are fitted.
"""

from __future__ import annotations

from riprs._riprs import FurutaParams, Plant

__all__ = ["FurutaParams", "Plant"]
