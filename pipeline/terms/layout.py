"""The observation contract, owned here once: what a features dataset stores and a policy reads, and the clock they
share. Every stage and both training backends take these names, widths and rates from this module.

**Clock.** Control at :data:`CONTROL_FPS` (50 Hz: the retargeted, physicalized and features datasets' frame rate,
and the policy's step); each control step holds its joint targets for :data:`SUBSTEPS` physics steps of
:data:`PHYSICS_TIMESTEP` (4 x 5 ms).

**Columns** (LeRobot feature names) and their per-frame widths:

==============================  ============  ==========================================================
column                          width         terms, in order
==============================  ============  ==========================================================
``observation.proprio``         93            q (29), dq (29), gravity in the root frame (3), root angular
                                              velocity in the root frame (3), the previous action (29)
``observation.root_command``    12            position delta (3), 6-D rotation (6), target velocity (3)
``observation.df``              10 K          per DF link: phi, grad phi (3), v_norm (3), v_tan (3)
``observation.df_relative``     10 K          the same with v relative to the object's closest surface point
``observation.df_demo``         4 x 7         the released demo's 7 bodies: min(|phi|, 1 m), grad in the body frame
``observation.df_object``       K             the nearest object per link (datasets with several objects)
``action``                      29            absolute joint position targets (mjlab order)
==============================  ============  ==========================================================

**A policy's observation** is the last :data:`HISTORY` steps of ``[proprio, root_command, df]``; flattened for an
RL library it is ``[proprio (l x 93), root_command (l x 12), df (l x 10 K)]`` (:meth:`ObservationLayout.flatten`),
and a critic's current step is ``[proprio, root_command, df]`` (:meth:`ObservationLayout.step_slices`). The AMP
discriminator reads :data:`AMP_STATE` of ``proprio``: the robot's state without the previous action.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.robot import G1_JOINT_NAMES, G1_LINK_NAMES, LESSMIMIC_DEMO_DF_BODIES, NUM_JOINTS
from pipeline.xp import concat, namespace

# -- the clock -------------------------------------------------------------------------------------------------------
CONTROL_FPS = 50
SUBSTEPS = 4
PHYSICS_TIMESTEP = 1.0 / (CONTROL_FPS * SUBSTEPS)  # 0.005 s, MuJoCo's timestep in every scene

# -- windows and commands --------------------------------------------------------------------------------------------
HISTORY = 5
"""l, the steps of the interaction window I_t and of the policy's history (the released demo's 5)."""
ROOT_HORIZON_S = 1.0
"""How far ahead the root command's target lies."""

# -- columns ---------------------------------------------------------------------------------------------------------
PROPRIO = "observation.proprio"
ROOT_COMMAND = "observation.root_command"
DF = "observation.df"
DF_RELATIVE = "observation.df_relative"
DF_DEMO = "observation.df_demo"
DF_OBJECT = "observation.df_object"
ACTION = "action"

# -- the DF feature --------------------------------------------------------------------------------------------------
DF_LINKS: tuple[str, ...] = G1_LINK_NAMES
DEMO_LINKS: tuple[str, ...] = LESSMIMIC_DEMO_DF_BODIES
DF_PARTS = ("phi", "grad_x", "grad_y", "grad_z", "v_norm_x", "v_norm_y", "v_norm_z", "v_tan_x", "v_tan_y", "v_tan_z")
DEMO_PARTS = ("phi", "grad_x", "grad_y", "grad_z")
DEMO_MAX_DISTANCE_M = 1.0

# -- proprioception and the root command -----------------------------------------------------------------------------
PROPRIO_NAMES: tuple[str, ...] = (
    tuple(f"q.{j}" for j in G1_JOINT_NAMES)
    + tuple(f"dq.{j}" for j in G1_JOINT_NAMES)
    + ("gravity_x", "gravity_y", "gravity_z")
    + ("ang_vel_x", "ang_vel_y", "ang_vel_z")
    + tuple(f"last_action.{j}" for j in G1_JOINT_NAMES)
)
ROOT_COMMAND_NAMES: tuple[str, ...] = (
    *("dpos_x", "dpos_y", "dpos_z"),
    *(f"rot6d_{i}" for i in range(6)),
    *("vel_x", "vel_y", "vel_z"),
)
PROPRIO_DIM, ROOT_COMMAND_DIM, ACTION_DIM = len(PROPRIO_NAMES), len(ROOT_COMMAND_NAMES), NUM_JOINTS
# -- observation contracts ---------------------------------------------------------------------------------------------
CONTRACTS = ("lessmimic", "lessmimic_demo")
"""What a policy observes. ``lessmimic``: the paper's, ``[proprio, root_command, df]`` with the 10-part DF of
:data:`DF_LINKS`. ``lessmimic_demo``: the released web demo's (its viewer's runner): the 4-part DF of
:data:`DEMO_LINKS` (``observation.df_demo``), a command of the current step only, without the height delta and the
vertical velocity (the viewer's movement goal has z = 0) and with its task condition appended
(:func:`pipeline.terms.observations.demo_command`), and unit-norm latents (:mod:`train.policy`)."""
CONTRACT_DF = {"lessmimic": (DF, DF_PARTS), "lessmimic_demo": (DF_DEMO, DEMO_PARTS)}
TASK_CONDITION = {"PickUp": 1.0, "Carry": 1.0, "Push": 2.0, "SitStand": 0.0}
"""The demo's task condition per task: 0 none, 1 carry, 2 push (its viewer's choices); PickUp is its carry
behaviour (lift and hold), SitStand its plain walking."""
DEMO_COMMAND_DIM = ROOT_COMMAND_DIM + 2


def check_contract(contract: str) -> str:
    if contract not in CONTRACTS:
        raise ValueError(f"unknown observation contract {contract!r}; known: {', '.join(CONTRACTS)}")
    return contract


AMP_STATE = slice(0, 2 * NUM_JOINTS + 6)
"""The columns of ``proprio`` the AMP discriminator reads: ``[q, dq, gravity_root, omega_root]`` (64)."""


def feature_names(links, parts=DF_PARTS) -> tuple[str, ...]:
    """Flat per-link names, ``<link>.<part>``, in the order the features are stored."""
    return tuple(f"{link}.{p}" for link in links for p in parts)


@dataclass(frozen=True)
class ObservationLayout:
    """A policy's observation: per step ``proprio`` (``proprio_dim``), ``root_command`` (``root_command_dim``) and
    ``df`` (``df_parts`` per link of ``links``: 10, or the demo contract's 4), over ``history`` steps."""

    links: tuple[str, ...] = DF_LINKS
    history: int = HISTORY
    proprio_dim: int = PROPRIO_DIM
    root_command_dim: int = ROOT_COMMAND_DIM
    df_parts: int = len(DF_PARTS)

    @property
    def df_dim(self) -> int:
        return self.df_parts * len(self.links)

    @property
    def step_dims(self) -> tuple[int, int, int]:
        """The widths of one step's ``proprio``, ``root_command`` and ``df`` terms."""
        return self.proprio_dim, self.root_command_dim, self.df_dim

    @property
    def flat_dim(self) -> int:
        return self.history * sum(self.step_dims)

    def step_slices(self) -> dict[str, slice]:
        """Where each term lies in one step's row ``[proprio, root_command, df]`` (a critic's observation)."""
        out, start = {}, 0
        for name, width in zip(("proprio", "root_command", "df"), self.step_dims):
            out[name], start = slice(start, start + width), start + width
        return out

    def flatten(self, proprio, root_command, df):
        """(N, l (P + C + 10K)): the three ``(N, l, dim)`` windows, each flattened, side by side (numpy or torch)."""
        n = len(proprio)
        return concat([proprio.reshape(n, -1), root_command.reshape(n, -1), df.reshape(n, -1)], namespace(proprio), 1)

    def split(self, flat):
        """The inverse of :meth:`flatten`: ``(B, l, dim)`` per term (torch)."""
        import torch

        parts = torch.split(flat, [self.history * d for d in self.step_dims], dim=-1)
        return tuple(p.reshape(len(flat), self.history, d) for p, d in zip(parts, self.step_dims))
