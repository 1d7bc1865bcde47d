"""The stateful decoders: the network model, SDO transfers, PDO and DBC signals, EMCY notes, CiA 402 drive states, the node tally and the event log."""
