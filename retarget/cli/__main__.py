"""``python -m retarget.cli``: the library's commands (the installed ``retarget`` command,
`server.cli`, adds ``serve``)."""

from retarget.cli import main

raise SystemExit(main())
