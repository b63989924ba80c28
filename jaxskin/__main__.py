"""`python -m jaxskin`: the same command line as the `jaxskin` script."""

from ._console import main

raise SystemExit(main())
