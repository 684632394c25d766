"""``python -m handle_drake.geometry.objects export <directory>``: regenerate the committed
models."""

import sys

from handle_drake.geometry.objects.sdf import export_models


def _main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] != "export":
        print("usage: python -m handle_drake.geometry.objects export <directory>", file=sys.stderr)
        return 2
    for path in export_models(argv[1]):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
