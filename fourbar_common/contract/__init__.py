"""The run folder's contract: one module per file that crosses from one part to another.

Every file a part writes for another to read has its home here -- its name
(:mod:`.layout`), its typed content (a frozen dataclass with ``to_json``/``from_json``, or
``read``/``write`` for a CSV), its schema version, and the errors a reader raises
(:class:`~.problems.ContractError`, carrying every problem found as (field, message)).
No other module spells one of these file names or parses one of these files.

Like the rest of :mod:`fourbar_common`, these modules import only the standard library (numpy
where a CSV's columns are arrays) and nothing of the parts.  Import the modules themselves
(``from fourbar_common.contract.layout import RunFolder``); this package re-exports nothing,
so adding a file's module never touches another's.
"""
