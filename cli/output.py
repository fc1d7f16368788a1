"""Where subcommands write: human text and tables, or JSON, on standard output."""

import json


class Output:
    """Standard output of one run.

    Parameters
    ----------
    stream : file
        Where results go (``sys.stdout``).
    quiet : bool
        Print nothing but ``--json`` output (asked for explicitly) and errors; the exit status
        carries the result.
    """

    def __init__(self, stream, quiet=False):
        self.stream, self.quiet = stream, quiet

    def text(self, text):
        if not self.quiet:
            print(text, file=self.stream)

    def table(self, header, rows, align=None, indent=""):
        from brdf.formatting import format_table
        lines = format_table(header, rows, align).splitlines()
        self.text("\n".join(indent + line for line in lines))

    def json(self, data):
        from brdf.formatting import json_ready
        print(json.dumps(json_ready(data), indent=2, allow_nan=False), file=self.stream)
