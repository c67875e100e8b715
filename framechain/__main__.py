from framechain.cli.main import main

raise SystemExit(main())
