"""Component FMUs from block files (docs/components.md): a component's parameters, inputs,
states and outputs as a small TOML file, read as data (``description``), derived with sympy
(``derivation``) and printed as C (``c_code``) for the native block model (fmu_src/native/block/).
``fmu_src/block_build.py`` builds the FMUs."""
