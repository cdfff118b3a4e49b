"""Physicalized (or retargeted) G1 motions in the files other trainers read: ``lessmimic export-motion``.

One module per concept:

* :mod:`motion_export.episodes` -- which episodes of which dataset are exported, read through the dataset readers;
* :mod:`motion_export.bodies` -- every body of the robot in mjlab's G1 entity order by forward kinematics: world
  positions, orientations (``wxyz``), linear and angular velocities (world), per frame;
* one writer per format (:data:`motion_export.stage.FORMATS`): :mod:`motion_export.npz` (mjlab's ``.npz``, and
  BeyondMimic's in Isaac Lab's order, :mod:`motion_export.isaaclab`), :mod:`motion_export.hdmi` (HDMI
  ``motion.npz`` + ``meta.json`` folders), :mod:`motion_export.gmr` (GMR ``.pkl``),
  :mod:`motion_export.unitree_csv` (Unitree's G1 retargeting ``.csv``, 30 Hz);
* :mod:`motion_export.sidecar` -- the JSON beside each motion: its source, actuator profile, physics, object
  geometry, synthetic start prefix and validation figures;
* :mod:`motion_export.stage` -- :func:`~motion_export.stage.export_motion`: the export folder, written whole or not
  at all.
"""

FORMAT_NAMES = (
    "mjlab-npz",
    "beyondmimic-npz",
    "hdmi",
    "gmr",
    "unitree-csv",
)  #: the formats, in :data:`motion_export.stage.FORMATS`
MOTION_STAGES = ("physicalized", "retargeted")  #: the stages a G1 motion is exported from (the first the default)
#: HDMI's rigid tracked objects (``object_asset_name`` of its ``cfg/task/G1/hdmi/*.yaml``): ``--hdmi-object`` choices;
#: its articulated ones (``door``, ``foldchair``) also need an object joint in ``joint_names``, which ours have not
HDMI_OBJECT_NAMES = ("suitcase", "box", "bread_box", "foam", "stool", "ball", "wood_board", "stair")
