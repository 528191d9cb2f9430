import signal

# Ctrl-C while Python loads the modules ends the process at once, quietly (no file is open yet);
# from the command's start on, it is the command's to handle (`run` turns it into a stop flag).
signal.signal(signal.SIGINT, signal.SIG_DFL)
from .cli.main import main  # noqa: E402

signal.signal(signal.SIGINT, signal.default_int_handler)
raise SystemExit(main())
