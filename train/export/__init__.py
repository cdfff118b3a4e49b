"""Trained policies out of torch: an interaction policy as one ONNX file with everything needed to run it written in
it (:mod:`train.export.onnx_policy`, its metadata :mod:`train.export.metadata`), and the onnxruntime policy that runs
such a file in our own evaluation harness (:mod:`train.export.runtime`)."""
