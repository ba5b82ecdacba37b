"""Position-only damped-least-squares IK of a drawing arm, with Pinocchio.

The pen tip has 3 position coordinates and the arm 4 joints, so each target
has a one-dimensional family of solutions. The solver takes, point after
point, the damped least-squares (Levenberg-Marquardt) step

    dq = J^T (J J^T + lambda^2 I)^-1 e,     e = target - FK(q),

the minimum-norm joint change, warm-started from the previous point's
solution: along a path of closely spaced targets it converges in 2-3
iterations and picks, among the solutions, the one nearest the previous
posture, so the joint path is continuous.

Joint limits are enforced by clamping; a joint at a limit that the step
would push further out is frozen (its Jacobian column dropped) and the step
recomputed on the others.

Unreachable targets: a point whose error stays above ``max_error`` after
the warm start and a few fixed restarts (the robot's home posture, the
middle of the joint ranges) raises :class:`~iloci.errors.UnreachableTargetError`
naming the point's index, its coordinates and the remaining error. The
solver never returns a path with a point it did not reach.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from iloci.linalg import matmul
from iloci.errors import InvalidInputError, UnreachableTargetError
from iloci.sensorimotor.robots import Robot, get_robot
from iloci.sensorimotor.robots.urdf import urdf_unicode

__all__ = ["PinocchioIK"]

#: Largest joint change of one iteration (rad); keeps a far first target from
#: overshooting into another solution branch.
_MAX_STEP = 0.5


class PinocchioIK:
    """The ``pinocchio`` IKSolver.

    Parameters
    ----------
    robot : str or Robot
        Robot name (see :func:`iloci.sensorimotor.robots.get_robot`) or
        a :class:`~iloci.sensorimotor.robots.Robot`.
    tolerance : float
        Stop iterating on a point once its position error is below this (m).
    max_error : float
        A point whose error stays above this is unreachable (m).
    max_iterations : int
        Iterations per point and start.
    damping : float
        Damping ``lambda`` (m).
    posture_gain : float
        Fraction of the way to the robot's rest posture taken per iteration
        in the null space of the pen-tip task (redundant arms with a
        ``rest`` posture only; 0 switches it off).

    Attributes
    ----------
    joint_names : tuple of str
        The ``J = 4`` actuated joints, in column order.
    lower, upper : ndarray, shape (J,)
        Joint limits (rad).
    robot : Robot
    """

    def __init__(self, robot: str | Robot = "nao-v32-right-arm", tolerance: float = 1e-7,
                 max_error: float = 1e-4, max_iterations: int = 100,
                 damping: float = 1e-3, posture_gain: float = 0.1) -> None:
        if not (0 < tolerance <= max_error):
            raise InvalidInputError(
                f"need 0 < tolerance <= max_error, got {tolerance} and {max_error}.")
        if int(max_iterations) < 1:
            raise InvalidInputError(f"max_iterations must be >= 1, got {max_iterations}.")
        if not damping >= 0:
            raise InvalidInputError(f"damping must be >= 0, got {damping}.")
        self.robot = robot if isinstance(robot, Robot) else get_robot(robot)
        self.tolerance = float(tolerance)
        self.max_error = float(max_error)
        self.max_iterations = int(max_iterations)
        self.damping = float(damping)

        self.posture_gain = float(posture_gain)
        if not 0 <= self.posture_gain <= 1:
            raise InvalidInputError(f"posture_gain must be in [0, 1], got {posture_gain}.")
        self._model, self._perm = _reduced_model(self.robot)
        self._data = self._model.createData()
        self._frame = self._model.getFrameId(self.robot.end_effector_frame)
        # the base frame's placement (fixed: no joint used moves it)
        pin.framesForwardKinematics(self._model, self._data, pin.neutral(self._model))
        base = self._model.getFrameId(self.robot.base_frame)
        oMb = self._data.oMf[base]
        self._base_R = None if np.allclose(oMb.rotation, np.eye(3)) and \
            np.allclose(oMb.translation, 0) else (oMb.rotation.copy(), oMb.translation.copy())
        self.joint_names = tuple(self.robot.joint_names)
        self.lower = np.array(self.robot.lower, dtype=np.float64)
        self.upper = np.array(self.robot.upper, dtype=np.float64)
        self._rest = None if self.robot.rest is None or self.posture_gain == 0 else \
            np.array(self.robot.rest, dtype=np.float64)
        # solving runs in the reduced model's joint order (self._perm: model -> robot
        # column); paths are reordered at the boundary when the orders differ
        self._lo_m, self._hi_m = self._to_model(self.lower), self._to_model(self.upper)
        self._rest_m = None if self._rest is None else self._to_model(self._rest)
        self._restarts = (self._to_model(np.array(self.robot.q_home, dtype=np.float64)),
                          (self._lo_m + self._hi_m) / 2)

    def _to_model(self, q: np.ndarray) -> np.ndarray:
        return q if self._perm is None else q[..., self._perm]

    def _to_robot(self, q: np.ndarray) -> np.ndarray:
        if self._perm is None:
            return q
        out = np.empty_like(q)
        out[..., self._perm] = q
        return out

    def __repr__(self) -> str:
        return f"PinocchioIK(robot={self.robot.name!r}, max_error={self.max_error})"

    # ---------------------------------------------------------------- forward
    def forward(self, q: np.ndarray) -> np.ndarray:
        """Pen-tip positions of joint configurations.

        Parameters
        ----------
        q : ndarray, shape (T, J) or (J,)
            Joint angles (rad), columns in :attr:`joint_names` order.

        Returns
        -------
        ndarray, shape (T, 3) or (3,)
            Pen-tip positions (m, torso frame).
        """
        qa = self._check_q(q, "q")
        single = qa.ndim == 1
        qs = qa[None] if single else qa
        out = np.empty((len(qs), 3))
        m, d, f = self._model, self._data, self._frame
        for i, qi in enumerate(self._to_model(qs)):
            pin.forwardKinematics(m, d, qi)
            out[i] = pin.updateFramePlacement(m, d, f).translation
        if self._base_R is not None:  # world -> base frame
            R, t = self._base_R
            out = matmul(out - t, R)
        return out[0] if single else out

    # ------------------------------------------------------------------ solve
    def solve(self, points: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray:
        """Joint path reaching each target, warm-started point to point.

        Parameters
        ----------
        points : ndarray, shape (T, 3)
            Pen-tip targets (m, torso frame).
        q0 : ndarray, shape (J,), optional
            Start configuration for the first point; defaults to the
            robot's ``q_home``. Must lie within the joint limits.

        Returns
        -------
        ndarray, shape (T, J)
            Joint angles (rad), within the limits, each reaching its target
            within ``max_error``.

        Raises
        ------
        InvalidInputError
            ``points`` is not a finite (T, 3) array with T >= 1, or ``q0`` is
            not a finite (J,) vector within the limits.
        UnreachableTargetError
            A target cannot be reached within ``max_error`` (names its index,
            coordinates and the remaining error).
        """
        try:
            pts = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInputError("IK targets must be a numeric array of shape (T, 3).") \
                from None
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
            raise InvalidInputError(
                f"IK targets must have shape (T, 3) with T >= 1 (x, y, z in metres, "
                f"torso frame), got {pts.shape}.")
        if not np.all(np.isfinite(pts)):
            row = int(np.argwhere(~np.isfinite(pts))[0, 0])
            raise InvalidInputError(f"IK target {row} is not finite ({pts[row].tolist()}).")
        if q0 is None:
            q = np.array(self.robot.q_home, dtype=np.float64)
        else:
            q = self._check_q(q0, "q0")
            if q.ndim != 1:
                raise InvalidInputError(f"q0 must have shape ({len(self.joint_names)},), "
                                        f"got {q.shape}.")
            if np.any(q < self.lower - 1e-9) or np.any(q > self.upper + 1e-9):
                raise InvalidInputError(
                    f"q0 {np.round(q, 4).tolist()} lies outside the joint limits "
                    f"[{np.round(self.lower, 4).tolist()}, {np.round(self.upper, 4).tolist()}].")
            q = q.copy()
        q = self._to_model(q)
        world = (pts if self._base_R is None
                 else matmul(pts, self._base_R[0].T) + self._base_R[1])
        path = np.empty((len(pts), len(self.joint_names)))
        for i, target in enumerate(world):
            q, err = self._solve_point(target, q)
            if err > self.max_error:
                best_q, best_err = q, err
                for start in self._restarts:
                    q, err = self._solve_point(target, start.copy())
                    if err < best_err:
                        best_q, best_err = q, err
                    if err <= self.max_error:
                        break
                q, err = best_q, best_err
                if err > self.max_error:
                    x, y, z = (float(v) for v in pts[i])
                    raise UnreachableTargetError(
                        f"IK target {i} of {len(pts)} at (x={x:.4f}, y={y:.4f}, z={z:.4f}) m "
                        f"is outside the reachable workspace of {self.robot.name!r}: the "
                        f"closest pen-tip position found is {err * 1000:.2f} mm away. Keep "
                        "targets inside the robot's drawing plane "
                        "(iloci.sensorimotor.robots.get_robot(...).plane).",
                        index=i, point=pts[i], error=err)
            path[i] = q
        return self._to_robot(path)

    def _solve_point(self, target: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, float]:
        """Damped least squares from ``q`` towards one target; returns (q, error)."""
        m, d, f = self._model, self._data, self._frame
        lo, hi = self._lo_m, self._hi_m
        rest, gain = self._rest_m, self.posture_gain
        lam2 = self.damping ** 2
        tol = self.tolerance
        tx, ty, tz = float(target[0]), float(target[1]), float(target[2])
        err = math.inf
        for it in range(self.max_iterations):
            pin.computeJointJacobians(m, d, q)
            p = pin.updateFramePlacement(m, d, f).translation
            e = np.array((tx - p[0], ty - p[1], tz - p[2]))
            err = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            # with a rest posture every point takes at least one step, so the
            # null-space pull acts even where the task is already met
            if err < tol and (rest is None or it > 0):
                break
            J = pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED)[:3]
            if rest is None:
                dq = _dls_step(J.tolist(), e, lam2)
            else:
                # task step plus a pull towards the rest posture projected on the
                # task's (damped) null space: z - J^+ J z
                z = gain * (rest - q)
                rows = J.tolist()
                dq = z + _dls_step(rows, e - _matvec(rows, z.tolist()), lam2)
            # freeze joints at a limit that the step pushes further out
            blocked = ((q <= lo) & (dq < 0)) | ((q >= hi) & (dq > 0))
            if blocked.any():
                J = J.copy()
                J[:, blocked] = 0.0
                if rest is None:
                    dq = _dls_step(J.tolist(), e, lam2)
                else:
                    z = np.where(blocked, 0.0, gain * (rest - q))
                    rows = J.tolist()
                    dq = z + _dls_step(rows, e - _matvec(rows, z.tolist()), lam2)
            big = float(np.abs(dq).max())
            if big > _MAX_STEP:
                dq *= _MAX_STEP / big
            q = np.minimum(np.maximum(q + dq, lo), hi)
        else:
            # the loop ran out: measure the error of the last step's result
            pin.forwardKinematics(m, d, q)
            p = pin.updateFramePlacement(m, d, f).translation
            err = math.dist((tx, ty, tz), (p[0], p[1], p[2]))
        return q, err

    def _check_q(self, q: np.ndarray, name: str) -> np.ndarray:
        J = len(self.joint_names)
        try:
            qa = np.asarray(q, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInputError(f"{name} must be a numeric array of shape (T, {J}) or "
                                    f"({J},).") from None
        if qa.shape[-1:] != (J,) or qa.ndim not in (1, 2):
            raise InvalidInputError(
                f"{name} must have shape (T, {J}) or ({J},) (joints "
                f"{', '.join(self.joint_names)}), got {qa.shape}.")
        if not np.all(np.isfinite(qa)):
            raise InvalidInputError(f"{name} contains NaN or inf.")
        return qa


def _reduced_model(robot: Robot) -> tuple[pin.Model, np.ndarray | None]:
    """The URDF's model with every joint but the robot's locked; and the joint order.

    Returns the model and ``perm``, the index array with
    ``q_model = q_robot[perm]``, or None when the orders agree.
    """
    try:
        # the text, decoded as the file declares (urdfdom reads UTF-8 only: a UTF-16 or
        # Latin-1 file that iloci accepts would otherwise fail here)
        full = pin.buildModelFromXML(urdf_unicode(robot.urdf_path))
    except (RuntimeError, ValueError) as exc:
        raise InvalidInputError(f"Pinocchio cannot read the URDF of {robot.name!r} "
                                f"({robot.urdf_path}): {exc}") from None
    names = [full.names[i] for i in range(1, full.njoints)]
    missing = [n for n in robot.joint_names if n not in names]
    if missing:
        raise InvalidInputError(f"URDF {robot.urdf_path} has no joint(s) {missing}; its "
                                f"joints are {names}.")
    for n in robot.joint_names:
        if full.joints[full.getJointId(n)].nq != 1:
            raise InvalidInputError(f"joint {n!r} of {robot.name!r} has "
                                    f"{full.joints[full.getJointId(n)].nq} coordinates; "
                                    "iloci drives one-coordinate joints only.")
    for frame, what in ((robot.end_effector_frame, "pen-tip"), (robot.base_frame, "base")):
        if not full.existFrame(frame):
            raise InvalidInputError(f"URDF {robot.urdf_path} has no {what} frame {frame!r}.")
    q_ref = pin.neutral(full)
    lock = []
    for n in names:
        if n in robot.joint_names:
            continue
        jid = full.getJointId(n)
        lock.append(jid)
        if n in robot.fixed_joints and full.joints[jid].nq == 1:
            q_ref[full.joints[jid].idx_q] = robot.fixed_joints[n]
    model = pin.buildReducedModel(full, lock, q_ref) if lock else full
    order = np.array([model.joints[model.getJointId(n)].idx_q for n in robot.joint_names])
    if model.nq != len(robot.joint_names):
        raise InvalidInputError(f"the reduced model of {robot.name!r} has {model.nq} "
                                f"coordinates for joints {robot.joint_names}.")
    # q_model[order[k]] = q_robot[k]  <=>  q_model = q_robot[argsort(order)]
    perm = np.argsort(order)
    return model, (None if np.array_equal(perm, np.arange(len(perm))) else perm)


def _dot(u: list[float], v: list[float]) -> float:
    """``sum_k u[k] v[k]`` in Python floats, ``k`` ascending from 0.0.

    The IK's small products are written out rather than left to numpy's
    ``@``: that calls OpenBLAS, whose kernels (chosen by CPU model) sum in
    other orders, so the same drawing gave joint paths that differed in
    their last bits from one x86-64 machine to another (and with them the
    memory learned from them). Python floats are IEEE doubles, one rounding
    per operation, the same on every machine.
    """
    acc = 0.0
    for x, y in zip(u, v):
        acc += x * y
    return acc


def _matvec(rows: list[list[float]], v: list[float]) -> np.ndarray:
    """``A v`` for ``A`` given as its rows, each element by :func:`_dot`."""
    return np.array([_dot(r, v) for r in rows])


def _dls_step(rows: list[list[float]], e: np.ndarray, lam2: float) -> np.ndarray:
    """``J^T (J J^T + lam2 I)^-1 e`` for a 3 x n ``J`` given as its 3 rows, with a closed-form
    3x3 solve.

    numpy's general solver costs ~7 us on a 3x3 system, more than the
    kinematics; the adjugate formula in Python floats is ~4x cheaper. Every
    sum in a fixed order (:func:`_dot`): the same bits on every CPU.
    """
    j0, j1, j2 = rows
    a, b, c = _dot(j0, j0), _dot(j0, j1), _dot(j0, j2)
    d, ee, f = _dot(j1, j1), _dot(j1, j2), _dot(j2, j2)
    a += lam2
    d += lam2
    f += lam2
    # adjugate of the symmetric matrix [[a, b, c], [b, d, ee], [c, ee, f]]
    A = d * f - ee * ee
    B = c * ee - b * f
    C = b * ee - c * d
    D = a * f - c * c
    E = b * c - a * ee
    F = a * d - b * b
    det = a * A + b * B + c * C
    if det == 0.0:
        return np.zeros(len(j0))
    x0, x1, x2 = e.tolist()
    y = [(A * x0 + B * x1 + C * x2) / det, (B * x0 + D * x1 + E * x2) / det,
         (C * x0 + E * x1 + F * x2) / det]
    return _matvec([list(col) for col in zip(*rows)], y)
