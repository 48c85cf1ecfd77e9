"""Learned motion matching (issue 27, docs/compressed.md): a controller that keeps a few
megabytes of networks instead of the database. The pose the networks reproduce
(:mod:`mmrl.compress.pose`), the networks (:mod:`mmrl.compress.networks`), their training
(:mod:`mmrl.compress.train`), file (:mod:`mmrl.compress.files`) and measures
(:mod:`mmrl.compress.measure`), and the trained controller ready to play
(:mod:`mmrl.compress.model`)."""
from .pose import forward_kinematics, pose_layout, pose_targets, rotation_6d_to_matrix
from .files import CompressedFileError, load_compressed, networks_from
from .measure import joint_errors_cm, reconstruct
from .networks import CompressConfig, CompressData
from .train import train_compressed

__all__ = ["CompressConfig", "CompressData", "CompressedFileError", "forward_kinematics", "joint_errors_cm",
           "load_compressed", "networks_from", "pose_layout", "pose_targets", "reconstruct", "rotation_6d_to_matrix",
           "train_compressed"]
