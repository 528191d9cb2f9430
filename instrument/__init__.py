"""A realtime stylistic walk synthesizer: HSMM style models, streaming MLPG, live control."""

__version__ = "0.1.0"
