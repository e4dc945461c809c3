#!../../bin/linux-x86_64/softIoc
# A startup script as EPICS softIoc runs it; beamctl runs it unchanged:
#   build/release/beamctl softioc examples/softioc/st.cmd      (from the repository root)
# Relative paths are taken from the current directory, as in iocsh: TOP says where this IOC is.
epicsEnvSet("TOP", "$(TOP=examples/softioc)")
epicsEnvSet("SYS", "LAB:")
cd "$(TOP)"

## Every st.cmd has these two lines; beamctl needs no .dbd and says it ignores them.
dbLoadDatabase "dbd/softIoc.dbd"
softIoc_registerRecordDeviceDriver(pdbbase)

dbLoadRecords("demo.db", "P=$(SYS)")
dbLoadTemplate("axes.substitutions", "SYS=$(SYS)")

iocInit

## After iocInit: a put processes the record, as a client's would.
dbpf $(SYS)m1:pos 12.5
dbl ao
