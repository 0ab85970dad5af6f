"""`plantreg demo` (placeholder until its issue lands)."""

from ..core.errors import PlantregError


def add_parser(sub):
    p = sub.add_parser("demo", help="(not yet implemented)")
    p.set_defaults(run=run)


def run(args):
    raise PlantregError("'demo' is not implemented yet")
