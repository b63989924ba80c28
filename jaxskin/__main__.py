"""`python -m jaxskin`: the same command line as the `jaxskin` script."""

from .cli import main

raise SystemExit(main())
