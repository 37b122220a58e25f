"""The lowest layer, below ``lenses``: what the scenes, the physics, the attackers and the runner all
use and none of them owns. Plugin discovery (``plugins``), the offline switches of ONNX Runtime and
Hugging Face (``offline``), plate rendering (``plate_render``) and random crops (``crops``).

It imports nothing of ours; ``tests/test_layers.py`` holds it to that.
"""
