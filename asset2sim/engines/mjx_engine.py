"""MJX engine: the MJCF export's physics stepped by MuJoCo XLA (``mujoco-mjx`` on JAX; on the CPU here), as a GPU
training scene runs it: no no-slip pass (MJX has none), pyramidal cones, the joints' own friction solver parameters.

The session is a :class:`~asset2sim.engines.mujoco_engine.MuJoCoSession` (the same in-memory MJCF of
:func:`asset2sim.engines.mjcf.urdf_to_mjcf`, the same queries answered from MuJoCo's host ``MjData``) whose
:meth:`MjxSession.step` runs ``mujoco.mjx.step`` instead of ``mj_step``: before a step, what the host data was told
(positions, velocities, applied efforts and forces, drives) is put into the MJX data; after it, positions and
velocities come back. One compiled (``jax.jit``) loop serves any number of steps. Contacts, penetration and link
frames are read from the host data at the stepped positions, as in MuJoCo.

Extra ``mjx``: ``pip install 'asset2sim[mjx]'`` (``mujoco-mjx``, ``jax`` on the CPU).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from asset2sim.engines.base import EngineTraits, HeldPhysics, SessionOptions, register_engine
from asset2sim.engines.mujoco_engine import MuJoCoSession
from asset2sim.engines.step_budget import spend


class MjxSession(MuJoCoSession):
    """A :class:`~asset2sim.engines.base.SimSession` stepped in MJX (see the module docstring).

    Raises:
        UrdfError, MjcfError: as :class:`MuJoCoSession`.
        ImportError: the extra ``mjx`` is missing (imported on first use).
        RuntimeError: MJX cannot take the model (``mujoco.mjx.put_model`` refuses a feature it lacks; the message
            names the file).
    """

    engine = "mjx"
    traits = EngineTraits()

    def __init__(self, urdf_path: Path, options: SessionOptions):
        super().__init__(urdf_path, options)
        import jax
        import jax.numpy as jnp
        from mujoco import mjx

        self._jnp = jnp
        try:
            self._mx = mjx.put_model(self.m)
            self._dx = mjx.put_data(self.m, self.d)
        except Exception as exc:  # NotImplementedError / ValueError naming the feature
            raise RuntimeError(f"MJX cannot take {urdf_path}: {exc}") from exc

        self._run = jax.jit(lambda mx, dx, n: jax.lax.fori_loop(0, n, lambda _, d: mjx.step(mx, d), dx))
        note = (f"stepped by MJX (mujoco.mjx.step, JAX on the {jax.default_backend().upper()}): "
                "no no-slip pass, the MJCF's cones and friction solver parameters")
        self.notes = [*self.notes, note]

    def _push(self) -> None:
        """The host data's state (its integration state, warm start included: :meth:`restore_state` restores what the
        next step starts from) and what is applied into the MJX data (before a step)."""
        jnp, d = self._jnp, self.d
        self._dx = self._dx.replace(qpos=jnp.asarray(d.qpos), qvel=jnp.asarray(d.qvel), act=jnp.asarray(d.act),
                                    qacc_warmstart=jnp.asarray(d.qacc_warmstart, dtype=self._dx.qacc_warmstart.dtype),
                                    qfrc_applied=jnp.asarray(d.qfrc_applied), xfrc_applied=jnp.asarray(d.xfrc_applied),
                                    time=jnp.asarray(d.time, dtype=self._dx.time.dtype))

    def _pull(self) -> None:
        """Positions, velocities and time of the MJX data back into the host data (after a step)."""
        dx, d = self._dx, self.d
        d.qpos[:] = np.asarray(dx.qpos)
        d.qvel[:] = np.asarray(dx.qvel)
        d.qacc_warmstart[:] = np.asarray(dx.qacc_warmstart)  # the solver's warm start: a restored state restores it too
        if self.m.na:
            d.act[:] = np.asarray(dx.act)
        d.time = float(dx.time)

    def step(self, n: int = 1) -> None:
        """Step ``n`` times in MJX: applied efforts and forces act for one step, drives are re-solved before every
        step (such steps run one at a time), the rest as one compiled loop."""
        remaining = int(n)
        if remaining <= 0:
            return
        spend(remaining)  # the refine's one budget of steps (asset2sim.engines.step_budget)
        while remaining:
            k = 1 if (self._drive or self._applied) else remaining
            if self._drive:
                self._forward()  # the mass matrix at the pulled positions, for the drive's gain
                self._apply_drives()
            self._push()
            self._dx = self._run(self._mx, self._dx, k)
            self._pull()
            self._clear_applied()
            remaining -= k
        self._mj.mj_kinematics(self.m, self.d)

    def held_physics(self) -> HeldPhysics:
        """As MuJoCo holds it (MJX takes the same ``MjModel``), named ``mjx``."""
        return dataclasses.replace(super().held_physics(), engine="mjx")


register_engine("mjx", MjxSession)
