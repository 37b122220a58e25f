"""Execution backends that attackers (and the utility net) share: ONNX Runtime export and sessions,
and the real-FFT convolution of the deconvolution attackers."""
