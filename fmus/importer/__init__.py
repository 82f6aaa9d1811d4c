"""FMU import: safe archive reading, modelDescription parsing, the fmpy runtime, process isolation and the
`FmuBlock` that makes an FMU a block."""
