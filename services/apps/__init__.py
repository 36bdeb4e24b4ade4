"""The composition root: the only package that wires several services together.

``cli`` (the ``pickplace`` command), ``up`` (every service in one process), ``launcher`` (one OS
process per service), ``cell`` (an in-process cell for tests and evaluation), ``evaluation``
(``pickplace eval``), ``vision_cli`` (the vision and calibration commands). Nothing imports it.
"""
