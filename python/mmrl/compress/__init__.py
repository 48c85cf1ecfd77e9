"""Learned motion matching (issue 27, docs/compressed.md): a controller that keeps a few
megabytes of networks instead of the database. This first part trains the compressor and the
decompressor (:mod:`mmrl.compress.train`) of the pose (:mod:`mmrl.compress.pose`)."""
from .pose import forward_kinematics, pose_layout, pose_targets, rotation_6d_to_matrix
from .train import (CompressConfig, CompressData, CompressedFileError, joint_errors_cm, load_compressed,
                    networks_from, reconstruct, train_compressed)

__all__ = ["CompressConfig", "CompressData", "CompressedFileError", "forward_kinematics", "joint_errors_cm",
           "load_compressed", "networks_from", "pose_layout", "pose_targets", "reconstruct", "rotation_6d_to_matrix",
           "train_compressed"]
