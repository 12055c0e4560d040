"""The CiA-402 master over Modbus TCP/RTU (pymodbus) and its register map."""
