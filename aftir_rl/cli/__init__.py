"""Command lines: the ``aftir`` dispatcher and one thin module per subcommand."""
