"""Sinks: btlog recordings written in other tools' formats (the mirror of ``btlog.sources``).

One module per format, each a function ``export_…(recording, output) -> ExportResult``:
``btcpp_filelog`` writes BehaviorTree.CPP's FileLogger2 ``.btlog``, which Groot2 opens;
``filelog_stream`` writes it while reading the recording, in bounded memory (what
``btlog export --to btlog`` uses when the file's events come in seq order).
"""
