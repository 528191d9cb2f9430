"""`python -m instrument`: the same entry point as the `instrument` console script."""

from .cli.main import main

raise SystemExit(main())
