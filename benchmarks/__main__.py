"""``python -m benchmarks [--quick] [--speed | --stress] [--out PATH]`` from the checkout's root:
the same as ``brdf-infer bench``."""

import sys

from brdf_infer.cli import main

sys.exit(main(["bench", *sys.argv[1:]]))
