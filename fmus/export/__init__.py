"""FMU export: modelDescription.xml, C sources (CasADi code + the FMI 2/3 layers in `templates/`), build, C host."""
