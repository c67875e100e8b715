from framechain.cli.main import entry

entry()
