"""The block kit: typed ports, parameters and equation blocks (`core`), graphs that wire them (`graph`),
generic blocks, Van der Pol neurons and CPG networks, leg geometry; one subpackage per paper (`yu`, `fukuhara`)."""
