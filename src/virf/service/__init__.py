"""VIRF over HTTP: the Logic Tutor kept warm for robot stacks (``virf serve``)."""
