"""Print the effective parameters: the built-in defaults with the user's file laid over them.

Every command reads its parameters the same way: ``--params FILE`` when given, else
``./params.yaml`` when the working directory has one, laid over the built-in defaults that
come with the package (mappings merge key by key; lists and values replace). This prints the
result, checked, as YAML a command's ``--params`` accepts; start a file of your own from it.

examples:
  navreplay params                          # everything in force here
  navreplay params --section run            # one section
  navreplay params --section filters.lc_ekf --params mine.yaml
"""

from __future__ import annotations

import argparse
import sys

from navreplay.pipeline.stages.options import add_params


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--section",
        metavar="DOTTED",
        help="print only this section (e.g. run, scenarios.named, filters.lc_ekf)",
    )
    add_params(parser)


def run(args: argparse.Namespace) -> int:
    import yaml

    from navreplay.pipeline.params import load_params, params_label, params_source, section

    params = load_params(args.params)  # checked: what a command would run with
    user = params_source(args.params)
    source = f"{user} over the built-in defaults" if user is not None else params_label()
    data = section(params, args.section) if args.section else None
    sys.stdout.write(f"# navreplay parameters: {source}\n")
    if args.section:
        sys.stdout.write(f"# section {args.section}\n")
        data = {args.section: data}
    else:
        from navreplay.ingest.typed import to_plain

        data = to_plain(params)
    sys.stdout.write(yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100))
    return 0
