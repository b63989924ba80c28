"""`python -m jaxskin.cli …`, the same as `jaxskin …`."""

import sys

from jaxskin.cli import main

sys.exit(main())
