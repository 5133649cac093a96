"""What a model uses, as compile-time switches of the step and rebuild kernels.

A feature a model lacks is compiled out (``wp.static`` in the kernel factories of step.py and neighbors.py):
a plain-sphere bed then carries no registers, loads or branches for clumps, mass tables, mesh walls, impact
records, coated walls, cohesive laws or rolling resistance. Each distinct set of features is one kernel
module, compiled once and cached by Warp.
"""

from dataclasses import dataclass

import numpy as np
import warp as wp

from .enums import ContactLaw, RollingModel
from .params import ContactHistory

MODULE_OPTIONS = {"enable_backward": False, "fast_math": True}
"""Options of every kernel module (``wp.set_module_options`` in each kernel file, ``module_options`` of each kernel
compiled per feature set). No gradients are taken. ``fast_math`` is CUDA-only (nvcc's ``--use_fast_math``:
division and square root to about 2 ulp, subnormals flushed to zero; Warp does not pass it to the CPU
compiler, so CPU results are unchanged and bit-reproducible). The laws divide and take roots at every contact;
on an H100 it raised the HM bed from 2.47e9 to 2.89e9 sphere-steps/s, the 8-sphere clump bed from 1.45e9 to
2.04e9 and the EEPA bed from 1.56e9 to 2.74e9, and ``warpdem verify --device cuda`` passes as before: single
precision already bounds the laws' accuracy far above 2 ulp."""

SMALL_CLUMP_SPHERES = 16
"""A clump of at most this many spheres is reduced and integrated by one thread on CUDA (step.integrate_clumps);
larger ones by a block of ``CLUMP_LANES`` threads, which would leave most lanes of a small clump idle."""


@dataclass(frozen=True)
class StepFeatures:
    """The features one model's kernels are compiled for (the defaults: everything)."""

    clumps: bool = True
    """The model has clumps: spheres reduce to their clump, and a clump's spheres skip each other."""
    share_mass: bool = True
    """Clump contacts damp a shared mass (``SolverOptions.clump_contact_mass == "shared"``): partner tables."""
    mesh_walls: bool = True
    """The model has triangle-mesh walls (and their impact records)."""
    coated_walls: bool = True
    """Spheres are glued to walls (``Model.attached_count``)."""
    cohesive_laws: bool = True
    """Some pair uses a law other than Hertz-Mindlin (JKR or EEPA)."""
    rolling: bool = True
    """Some pair has a rolling model and a rolling friction above zero."""
    rolling_spring: bool = True
    """Some pair has EPSD rolling resistance (a rolling friction above zero), whose spring is history."""
    large_clumps: bool = True
    """Some clump has more than ``SMALL_CLUMP_SPHERES`` spheres: on CUDA, clumps integrate over blocks of lanes."""
    rolling_standard: bool = True
    """Some pair has EDEM's standard rolling friction (a rolling friction above zero): the step branches on the
    pair's model per contact and reads each clump's centre of mass. Left out of the other models' kernel, whose
    clump and rolling path it slowed by 13-30 % on the CPU."""

    @property
    def history_type(self):
        """What a list slot stores (kernels/params.py, ``history_load``/``history_store``): the whole
        ``ContactHistory`` (28 bytes) when an EPSD spring needs it; the tangential spring and the law's scalar,
        a ``wp.vec4`` (16 bytes), for cohesive laws without EPSD; else only the spring, a ``wp.vec3`` (12 bytes).
        The history moves through memory twice per contact and step (the bytes the step kernel waits on) and is
        most of a sphere's memory."""
        if self.rolling_spring:
            return ContactHistory
        return wp.vec4 if self.cohesive_laws else wp.vec3

    @staticmethod
    def of(model, share_mass: bool) -> "StepFeatures":
        """The features of ``model`` (duck-typed: clump_count, clump_sphere_start/end, wall_count, attached_count,
        pair_params)."""
        pairs = model.pair_params.numpy()
        rolling = (pairs["rolling_model"] != int(RollingModel.NONE)) & (pairs["mu_r"] != 0.0)
        epsd = (pairs["rolling_model"] == int(RollingModel.EPSD)) & (pairs["mu_r"] != 0.0)
        standard = (pairs["rolling_model"] == int(RollingModel.STANDARD)) & (pairs["mu_r"] != 0.0)
        clumps = model.clump_count > 0
        spheres = model.clump_sphere_end.numpy() - model.clump_sphere_start.numpy() if clumps else np.zeros(1)
        return StepFeatures(
            clumps=clumps,
            share_mass=clumps and bool(share_mass),
            mesh_walls=model.wall_count > 0,
            coated_walls=model.attached_count > 0,
            cohesive_laws=bool(np.any(pairs["law"] != int(ContactLaw.HERTZ_MINDLIN))),
            rolling=bool(np.any(rolling)),
            rolling_spring=bool(np.any(epsd)),
            large_clumps=bool(spheres.max() > SMALL_CLUMP_SPHERES),
            rolling_standard=bool(np.any(standard)),
        )
