"""A third-party style output for registry tests (loaded through an entry point)."""

from rts_scenario.outputs import Output


class DummyOutput(Output):
    name = "dummy"

    def __init__(self, argument: str = "") -> None:
        super().__init__()
        self.argument = argument
        self.frames = 0
        self.closes = 0

    def _write(self, batch):
        self.frames += batch.n_frames

    def _close(self):
        self.closes += 1
