"""A run: the runner that walks one robot's plan, the ensemble that keeps several on one show
clock, the session that opens links, music and the recorder and closes them, and replay."""
