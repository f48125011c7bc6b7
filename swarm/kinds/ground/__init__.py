"""The ``ground`` vehicle kind: the TPODS MK-E module on a table, driven by four mecanum wheels (paper
section VI-A).

``params`` holds its tables (``[kinds.ground.body]``, ``wheels``, ``control``, ``dispersions``),
``dynamics`` the compiled planar truth step (mecanum kinematics, first-order motor lag, wheel saturation,
slip) and ``control`` the discrete LQR on the lagged velocity plant with the yaw law and the mecanum
inverse kinematics.
"""
