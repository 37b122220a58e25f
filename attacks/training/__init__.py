"""What trained attackers share: the restorer and plate-reader training loops, the training
degradations, and the shipped-weights store (``attacks/weights/``)."""
