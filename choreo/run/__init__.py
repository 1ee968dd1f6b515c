"""A run: its settings settled once before anything opens (settings, sections), the stage that
opens its log and links and closes them (stage), the session that plays its passes on a show
clock (session), the runner that walks one robot's plan, the ensemble that keeps several on one
show clock, and replay, a run of a recorded log's frames."""
