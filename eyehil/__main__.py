"""`python -m eyehil ...` is the `eyehil` command."""

from eyehil.cli import main

raise SystemExit(main())
