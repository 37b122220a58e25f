"""The stages of the licence-plate attack (``attacks/readers/lpdr.py``), one module each, and what the
learned reader shares with it.

``vehicles`` (segmentation or ground truth) -> plate detection inside each vehicle (``detect_craft``
or ``detect_opencv``) -> OCR (``ocr``: EasyOCR english_g2, its convolutions through ONNX Runtime in
``ocr_onnx``), with EasyOCR's weights loaded offline (``easyocr_models``); ``memo`` remembers what the
deterministic stages computed, by the content of their input. ``plate_sim`` simulates plates through a
camera, for the learned reader (``attacks/readers/learned_reader.py``) to train on.
"""
