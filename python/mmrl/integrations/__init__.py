"""Bridges to other tools: the policy as ONNX (:mod:`mmrl.integrations.onnx_export`)."""
