"""A trained run for other programs: the runtime controller file that the C++ ``mmrl_runtime``
loads (``runtime_file``: the format; ``runtime_export``: what goes in it) and the policy as ONNX
(``onnx_export``)."""
