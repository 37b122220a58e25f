"""The stages of the licence-plate attack (``attacks/readers/lpdr.py``), one module each.

vehicles (segmentation or ground truth) -> plate detection inside each vehicle (CRAFT or
OpenCV) -> OCR (EasyOCR english_g2), with EasyOCR's weights loaded offline.
"""
