"""The twin's model files (MJCF) and ``make_scene``, the generator of ``scene.xml``, whose
constants are the arena's dimensions (README.md here says where each number comes from)."""
