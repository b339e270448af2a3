"""Studies built on the library: the speed/accuracy trade (``accuracy``)."""
