"""A test output: what the live loop sent it, frame by frame."""


class FrameIndices:
    """An output that keeps the index of every frame it is sent."""

    name = "frames"

    def __init__(self):
        self.indices: list[int] = []

    def prepare(self, frame):
        return frame.index

    def send(self, index):
        self.indices.append(index)

    def close(self):
        pass
