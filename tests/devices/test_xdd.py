"""CiA 311 XDD/XDC device files read wherever an EDS/DCF is: a real XDD against the same
device's EDS (tests/data/xdd, CANopenDemo), an XDC's actualValue as a DCF's ParameterValue,
`--eds NODE=x.xdd` end to end, and hostile XML refused in one line."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest
from canopen.objectdictionary import import_od
from conftest import ROOT

from cananalyze.cli.main import main
from cananalyze.core.errors import InputError
from cananalyze.devices import xdd
from cananalyze.devices.eds import read_od
from cananalyze.devices.profile import load_eds

DATA = ROOT / "tests" / "data" / "xdd"
XDD = DATA / "demoDevice.xdd"
EDS = DATA / "demoDevice.eds"


def variables(od) -> dict:
    out = {}
    for obj in od.values():
        for var in obj.subindices.values() if hasattr(obj, "subindices") else [obj]:
            out[(var.index, var.subindex)] = var
    return out


def no_default_as_none(value):
    """An EDS's empty `DefaultValue=` is '' (b'' for a DOMAIN); an XDD leaves it out."""
    return None if value in ("", b"") else value


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, cwd=ROOT
    )


def test_real_xdd_has_the_objects_of_the_same_devices_eds():
    from_xdd = variables(read_od(XDD, 5))
    from_eds = variables(read_od(EDS, 5))
    independent = variables(import_od(str(EDS), 5))
    assert len(from_xdd) == 288  # 0x1280, disabled in the project (CO_disabled), left out
    assert set(from_xdd) == set(from_eds) == set(independent)
    for key, x in from_xdd.items():
        for eds in (from_eds[key], independent[key]):
            where = f"0x{key[0]:04X}:{key[1]:02X}"
            assert x.name == eds.name, where
            assert x.data_type == eds.data_type, where
            assert x.access_type == eds.access_type, where
            assert x.pdo_mappable == eds.pdo_mappable, where
            assert (x.min, x.max) == (eds.min, eds.max), where
            assert no_default_as_none(x.default) == no_default_as_none(eds.default), where
    # a few read off the XML by eye: parameter elements through uniqueIDRef
    assert from_xdd[(0x1000, 0)].default == 0x000F0191 and from_xdd[(0x1000, 0)].data_type == 7
    assert from_xdd[(0x1400, 1)].default_raw == "$NODEID+0x00000200"
    assert from_xdd[(0x1400, 1)].default == 0x205 and from_xdd[(0x1400, 1)].relative
    assert from_xdd[(0x1A00, 1)].default == 0x60000108
    assert from_xdd[(0x2121, 3)].default == bytes.fromhex("C83DBB")  # BITSTRING: OCTET_STRING
    assert from_xdd[(0x2122, 0)].data_type == 0x0F  # BITSTRING without a default: DOMAIN
    assert from_xdd[(0x1017, 0)].access_type == "rw" and from_xdd[(0x1000, 0)].access_type == "ro"


def test_real_xdd_profile_is_the_eds_profile():
    a, b = load_eds(XDD), load_eds(EDS)
    for p in (a, b):
        identity = (p.vendor_id, p.product_code, p.device_type, p.device_name, p.name)
        assert identity == (0, 1, 0x000F0191, "Demo device", "Demo device")
    assert a.pdos(5) == b.pdos(5) and len(a.pdos(5)) == 8
    tx1 = next(p for p in a.pdos(5) if p.direction == "tx" and p.number == 1)
    assert tx1.cob_id == 0x185
    assert [(e.index, e.subindex, e.bits) for e in tx1.mapping][:2] == [
        (0x6000, 1, 8),
        (0x6000, 2, 8),
    ]
    info_a, info_b = read_od(XDD).device_information, read_od(EDS).device_information
    assert info_a.allowed_baudrates == info_b.allowed_baudrates
    assert (info_a.nr_of_RXPDO, info_a.nr_of_TXPDO) == (info_b.nr_of_RXPDO, info_b.nr_of_TXPDO)


def _configured(tmp_path):
    """(XDC, DCF) of the demo device configured alike: node 9, heartbeat 250 ms (the
    object's actualValue attribute), TPDO1's first entry 0x62000108 (the parameter's
    actualValue element), written from the real XDD and EDS."""
    text = XDD.read_text(encoding="utf-8")
    text = text.replace(
        '<CANopenObject index="1017" name="Producer heartbeat time" objectType="7" ',
        '<CANopenObject index="1017" name="Producer heartbeat time" objectType="7" '
        'actualValue="250" ',
    )
    text = re.sub(
        r'(<q1:parameter uniqueID="UID_SUB_1A0001"[^>]*>.*?<q1:defaultValue value="[^"]*" />)',
        r'\1<q1:actualValue value="0x62000108" />',
        text,
        count=1,
        flags=re.S,
    )
    text = text.replace(
        "<CANopenMasterFeatures />",
        '<CANopenMasterFeatures /><deviceCommissioning nodeID="9" nodeName="demo" '
        'actualBaudRate="250 Kbps" />',
    )
    assert text.count("actualValue") == 2 and "deviceCommissioning" in text
    xdc = tmp_path / "demo.xdc"
    xdc.write_text(text, encoding="utf-8")
    eds = EDS.read_text(encoding="utf-8")
    eds = eds.replace("[1017]\n", "[1017]\nParameterValue=250\n", 1)
    eds = eds.replace("[1A00sub1]\n", "[1A00sub1]\nParameterValue=0x62000108\n", 1)
    eds += "\n[DeviceComissioning]\nNodeID=9\nBaudrate=250\n"
    dcf = tmp_path / "demo.dcf"
    dcf.write_text(eds, encoding="utf-8")
    return xdc, dcf


def test_xdc_actual_value_is_the_configured_value(tmp_path):
    xdc, dcf = _configured(tmp_path)
    od = read_od(xdc)
    assert od.node_id == 9 and od.bitrate == 250_000
    assert od[0x1017].value == 250 and od[0x1017].default == 0
    assert od[0x1A00][1].value == 0x62000108 and od[0x1A00][1].default == 0x60000108
    assert od[0x1400][1].default == 0x209  # $NODEID is the XDC's node
    prof, ref = load_eds(xdc), load_eds(dcf)
    assert prof.node_id == ref.node_id == 9
    assert prof.value(0x1017, 0) == ref.value(0x1017, 0) == 250
    assert prof.object(0x1017).default == ref.object(0x1017).default == 250
    assert prof.pdos(9) == ref.pdos(9)
    tx1 = next(p for p in prof.pdos(9) if p.direction == "tx" and p.number == 1)
    assert (tx1.cob_id, tx1.mapping[0].index) == (0x189, 0x6200)
    # as with a DCF, an explicit node ID wins over the file's
    assert read_od(xdc, 3).node_id == 3 and read_od(xdc, 3)[0x1400][1].default == 0x203


LOG = (
    "(1.000000) can0 605#2310210178563412\n"  # write 0x2110:01 = 0x12345678
    "(1.001000) can0 585#6010210100000000\n"
    "(1.100000) can0 605#4020210200000000\n"  # read 0x2120:02
    "(1.101000) can0 585#4320210278563412\n"
)


def test_decode_names_sdo_transfers_from_the_xdd(tmp_path):
    log = tmp_path / "bus.log"
    log.write_text(LOG)

    def transfers(*extra: str) -> tuple[list[dict], str]:
        out = cli("decode", str(log), "--format", "jsonl", *extra)
        assert out.returncode == 0, out.stderr.decode()
        text = out.stdout.decode()
        return [r for r in map(json.loads, text.splitlines()) if r["kind"] == "sdo"], text

    bare, _ = transfers()
    named, text = transfers("--eds", f"5={XDD}")
    [(w, r)] = [tuple(named)]
    assert (w["index"], w["subindex"], w["name"], w["value"]) == (0x2110, 1, "int32", 0x12345678)
    assert (r["index"], r["subindex"], r["name"]) == (0x2120, 2, "U64")
    assert all(t["name"] not in ("int32", "U64") for t in bare)
    assert transfers("--eds", f"5={EDS}")[1] == text  # the same as the device's EDS gives
    shown = cli("decode", str(log), "--no-color", "--eds", f"5={XDD}").stdout.decode()
    assert "SDO write 0x2110:01 int32 expedited -> ok: 305419896 (0x12345678)" in shown


def test_xdd_in_network_file_and_devices(tmp_path, capsys):
    log = tmp_path / "bus.log"
    log.write_text(LOG)
    net = tmp_path / "net.toml"
    net.write_text(f'[nodes.5]\neds = "{XDD.as_posix()}"\n')
    assert main(["decode", str(log), "--network", str(net), "--format", "jsonl"]) == 0
    names = [json.loads(x).get("name") for x in capsys.readouterr().out.splitlines()]
    assert "int32" in names and "U64" in names
    assert main(["devices", str(XDD), "--node", "5"]) == 0
    shown = capsys.readouterr().out
    assert "Demo device" in shown and "TPDO1 COB-ID 0x185" in shown


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
 <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
 <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
 <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
 <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<ISO15745ProfileContainer><CANopenObjectList>
<CANopenObject index="1008" name="&lol9;" objectType="7" dataType="0009"/>
</CANopenObjectList></ISO15745ProfileContainer>
"""
EXTERNAL = """<?xml version="1.0"?>
<!DOCTYPE x [<!ENTITY x SYSTEM "file:///etc/passwd">]>
<ISO15745ProfileContainer><CANopenObjectList>
<CANopenObject index="1008" name="&x;" objectType="7" dataType="0009"/>
</CANopenObjectList></ISO15745ProfileContainer>
"""
DEEP = (
    "<ISO15745ProfileContainer>"
    + "<a>" * 100_000
    + "</a>" * 100_000
    + "</ISO15745ProfileContainer>"
)


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        ("laughs.xdd", BILLION_LAUGHS, "DTD or entities"),
        ("external.xdc", EXTERNAL, "DTD or entities"),
        ("deep.xdd", DEEP, "nested more than 64 deep"),
        (
            "broken.xdd",
            "<ISO15745ProfileContainer><a></ISO15745ProfileContainer>",
            "XML mismatched",
        ),
        ("other.xdd", "<html><body/></html>", "root element is <html>"),
        (
            "encoding.xdd",
            '<?xml version="1.0" encoding="FFFFFFFF"?><ISO15745ProfileContainer/>',
            "unknown encoding",
        ),
    ],
    ids=["billion-laughs", "external-entity", "deep-nesting", "broken", "not-cia311", "encoding"],
)
def test_hostile_xml_is_refused_in_one_line(tmp_path, name, content, says):
    log = tmp_path / "bus.log"
    log.write_text(LOG)
    bad = tmp_path / name
    bad.write_text(content)
    out = cli("decode", str(log), "--eds", f"5={bad}")
    err = out.stderr.decode()
    assert out.returncode == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert name in err and says in err


def test_xml_size_is_bounded_and_content_picks_the_reader(tmp_path, monkeypatch):
    monkeypatch.setattr(xdd, "MAX_BYTES", 1000)
    big = tmp_path / "big.xdd"
    big.write_text("<ISO15745ProfileContainer>" + " " * 2000 + "</ISO15745ProfileContainer>")
    with pytest.raises(InputError, match=r"big\.xdd: refused: an XDD/XDC larger than"):
        read_od(big)
    monkeypatch.undo()
    # an XDD saved with the wrong suffix is still read as XML, and an EDS as an EDS
    renamed = tmp_path / "demo.eds"
    renamed.write_bytes(XDD.read_bytes())
    assert len(variables(read_od(renamed, 5))) == 288
    notes = tmp_path / "notes.xml"
    notes.write_text("<ISO15745ProfileContainer/>")
    with pytest.raises(InputError, match="not an EDS, DCF, XDD or XDC"):
        read_od(notes)


def test_xdc_is_a_configuration_reference_and_a_dcf_base_as_a_dcf_is(tmp_path):
    xdc, dcf = _configured(tmp_path)
    log = tmp_path / "cfg.log"
    log.write_text(  # node 9's heartbeat written to 100 ms; the XDC/DCF configure 250 ms
        "(1.000000) can0 609#2B17100064000000\n(1.001000) can0 589#6017100000000000\n"
    )
    against = {}
    for ref in (xdc, dcf):
        out = cli("diff", str(log), str(ref))
        assert out.returncode == 1, out.stderr.decode()
        against[ref.suffix] = out.stdout.decode().replace(str(ref), "B")
    assert "0x1017:00 Producer heartbeat time: 100 -> 250" in against[".xdc"]
    assert against[".xdc"] == against[".dcf"]
    out = cli("od", str(log), "--eds", f"9={xdc}", "--dcf", str(tmp_path / "dcf"))
    assert out.returncode == 0, out.stderr.decode()
    written = import_od(str(tmp_path / "dcf" / "node9.dcf"))
    assert written.node_id == 9 and written[0x1017].value == 100
    assert written[0x1000].description.startswith("* bit 16-31: Additional information")


# -- more real files (tests/data/xdd/README.md): CANopenNode's DS301 profile as
# CANopenEditor's project file (.xpd, an XDD with CANopenNode's properties) beside the EDS
# exported from it, and EdsDcfNet's XDC (another writer, deviceCommissioning written as
# CiA 311 has it).
XPD = DATA / "DS301_profile.xpd"
XPD_EDS = DATA / "DS301_profile.eds"
XDC_MINIMAL = DATA / "minimal.xdc"


def _readable_eds(tmp_path):
    """The DS301 EDS with its empty `VendorNumber=`/`ProductNumber=` given 0, for canopen's
    import_od, which stops at an empty DeviceInfo number (cananalyze reads the file as
    CANopenNode ships it, passing over the empty entries)."""
    with pytest.raises(ValueError, match="invalid literal for int"):
        import_od(str(XPD_EDS))
    text = XPD_EDS.read_text(encoding="utf-8")
    assert text.count("\nVendorNumber=\n") == 1 and text.count("\nProductNumber=\n") == 1
    text = text.replace("\nVendorNumber=\n", "\nVendorNumber=0\n")
    text = text.replace("\nProductNumber=\n", "\nProductNumber=0\n")
    eds = tmp_path / "DS301_profile.eds"
    eds.write_text(text, encoding="utf-8")
    return eds


def test_real_xpd_has_the_objects_of_the_eds_exported_from_it(tmp_path):
    eds = _readable_eds(tmp_path)
    from_xpd = variables(read_od(XPD, 5))
    from_eds = variables(read_od(XPD_EDS, 5))  # as shipped
    assert variables(read_od(eds, 5)).keys() == from_eds.keys()
    independent = variables(import_od(str(eds), 5))
    assert len(from_xpd) == 176  # objects marked CO_disabled in the project left out, as the EDS
    assert set(from_xpd) == set(from_eds) == set(independent)
    for key, x in from_xpd.items():
        for ref in (from_eds[key], independent[key]):
            where = f"0x{key[0]:04X}:{key[1]:02X}"
            assert x.name == ref.name, where
            assert x.data_type == ref.data_type, where
            assert x.access_type == ref.access_type, where
            assert x.pdo_mappable == ref.pdo_mappable, where
            assert (x.min, x.max) == (ref.min, ref.max), where
            assert no_default_as_none(x.default) == no_default_as_none(ref.default), where
            assert x.relative == ref.relative, where
    assert from_xpd[(0x1014, 0)].default_raw.upper() == "$NODEID+0X80"
    assert from_xpd[(0x1014, 0)].default == 0x85
    a, b = load_eds(XPD), load_eds(XPD_EDS)
    assert (a.device_type, a.device_name, a.name) == (b.device_type, b.device_name, b.name)
    assert read_od(XPD_EDS).device_information.vendor_number is None  # left out, not 0
    assert a.pdos(5) == b.pdos(5) and len(a.pdos(5)) == 8
    assert {p.cob_id for p in a.pdos(5) if p.direction == "tx"} == {0x185, 0x285, 0x385, 0x485}
    info_a, info_b = read_od(XPD).device_information, read_od(XPD_EDS).device_information
    assert info_a.allowed_baudrates == info_b.allowed_baudrates
    assert (info_a.nr_of_RXPDO, info_a.nr_of_TXPDO) == (info_b.nr_of_RXPDO, info_b.nr_of_TXPDO)
    assert info_a.LSS_supported is info_b.LSS_supported is True


def test_xpd_is_a_device_file_on_the_command_line(tmp_path):
    log = tmp_path / "bus.log"
    log.write_text(  # read 0x1017 (heartbeat) from node 5: 1000 ms
        "(1.000000) can0 605#4017100000000000\n(1.001000) can0 585#4B171000E8030000\n"
    )
    out = cli("decode", str(log), "--no-color", "--eds", f"5={XPD}")
    assert out.returncode == 0, out.stderr.decode()
    assert "SDO read 0x1017:00 Producer heartbeat time expedited -> ok: 1000" in out.stdout.decode()
    shown = cli("devices", str(XPD), "--node", "5")
    assert shown.returncode == 0, shown.stderr.decode()
    assert "New Product" in shown.stdout.decode()


def test_real_xdc_of_another_writer_gives_node_bitrate_and_values(tmp_path):
    od = read_od(XDC_MINIMAL)
    assert od.node_id == 5 and od.bitrate == 500_000
    assert od.device_information.allowed_baudrates == {250_000, 500_000}
    assert (od[0x1000].value, od[0x1000].default) == (0x191, 0)
    assert (od[0x1001].value, od[0x1001].default) == (0, 0)
    assert od.device_information.vendor_number == 0x100
    prof = load_eds(XDC_MINIMAL)
    assert prof.node_id == 5 and prof.value(0x1000, 0) == 0x191
    # a log where node 5 answers 0x1000 with what the XDC configures, then with another value
    same, other = tmp_path / "same.log", tmp_path / "other.log"
    same.write_text("(1.0) can0 605#4000100000000000\n(1.001) can0 585#4300100091010000\n")
    other.write_text("(1.0) can0 605#4000100000000000\n(1.001) can0 585#4300100092010000\n")
    assert cli("diff", str(same), str(XDC_MINIMAL)).returncode == 0
    differs = cli("diff", str(other), str(XDC_MINIMAL))
    assert differs.returncode == 1, differs.stderr.decode()
    assert "configuration: 0x1000:00 Device type: 402 -> 401" in differs.stdout.decode()
    # and the DCF written from the log with the XDC as the node's description
    out = cli("od", str(other), "--eds", f"5={XDC_MINIMAL}", "--dcf", str(tmp_path / "dcf"))
    assert out.returncode == 0, out.stderr.decode()
    written = import_od(str(tmp_path / "dcf" / "node5.dcf"))
    assert written.node_id == 5 and written[0x1000].value == 0x192


# The commissioning shapes of two vendor XDCs seen in public repositories whose licence is
# unknown (so the files are not shipped; see tests/data/xdd/README.md): FAULHABER Motion
# Manager 6 writes nodeID="0" actualBaudRate="125", maxon's EPOS3 nodeID="0"
# actualBaudRate="1000000". Node 0 is "not commissioned", not node 0.
@pytest.mark.parametrize(
    ("node", "rate", "want_node", "want_rate"),
    [
        ("0", "125", None, 125_000),
        ("0", "1000000", None, 1_000_000),
        ("5", "250 Kbps", 5, 250_000),
        ("12", "1 Mbps", 12, 1_000_000),
        ("127", "auto-baudRate", 127, None),
        ("200", "", None, None),
    ],
)
def test_vendor_commissioning_shapes(tmp_path, node, rate, want_node, want_rate):
    text = XDC_MINIMAL.read_text(encoding="utf-8")
    text = text.replace('nodeID="5"', f'nodeID="{node}"', 1)
    text = text.replace('actualBaudRate="500 Kbps"', f'actualBaudRate="{rate}"', 1)
    xdc = tmp_path / "vendor.xdc"
    xdc.write_text(text, encoding="utf-8")
    od = read_od(xdc)
    assert (od.node_id, od.bitrate) == (want_node, want_rate)
    assert od[0x1000].value == 0x191


# maxon's EPOS3 XDC (not shipped, see the README) describes objects in attributes with
# two-digit data types, empty defaults, PDOmapping="TPDO"/"RPDO" and signed values in hex.
EPOS3_SHAPES = """
<CANopenObject index="2004" name="SerialNumber" objectType="7" dataType="1B" accessType="ro"
  defaultValue="" PDOmapping="no" objFlags="0001" actualValue="0x0000602095000659"/>
<CANopenObject index="6041" name="Statusword" objectType="7" dataType="06" accessType="ro"
  defaultValue="" PDOmapping="TPDO" objFlags="0003"/>
<CANopenObject index="6040" name="Controlword" objectType="7" dataType="06" accessType="rw"
  defaultValue="" PDOmapping="RPDO" objFlags="0001" actualValue="0x0000"/>
<CANopenObject index="607D" name="Software Position Limit" objectType="9" subNumber="3">
  <CANopenSubObject subIndex="00" name="Number of Entries" objectType="7" dataType="05"
    accessType="ro" defaultValue="" PDOmapping="no" objFlags="0003"/>
  <CANopenSubObject subIndex="01" name="Min Position Limit" objectType="7" dataType="04"
    accessType="rw" defaultValue="-2147483648" PDOmapping="no" actualValue="0x80000000"/>
  <CANopenSubObject subIndex="02" name="Max Position Limit" objectType="7" dataType="04"
    accessType="rw" defaultValue="2147483647" PDOmapping="no" actualValue="0x7FFFFFFF"/>
</CANopenObject>
<CANopenObject index="60E3" name="Supported Homing Methods" objectType="9" subNumber="2">
  <CANopenSubObject subIndex="00" name="Highest Sub-Index Supported" objectType="7"
    dataType="05" accessType="ro" defaultValue="" PDOmapping="no" actualValue="0x01"/>
  <CANopenSubObject subIndex="01" name="1st Supported Homing Method" objectType="7"
    dataType="03" accessType="ro" defaultValue="-1" PDOmapping="no" actualValue="0xFFFF"/>
</CANopenObject>
"""
SIGNED_DCF = """[DeviceInfo]
VendorName=x
VendorNumber=0xFB
ProductName=x
ProductNumber=0
[MandatoryObjects]
SupportedObjects=1
1=0x1000
[1000]
ParameterName=Device Type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00020192
PDOMapping=0
[OptionalObjects]
SupportedObjects=1
1=0x607D
[607D]
ParameterName=Software Position Limit
ObjectType=0x9
SubNumber=3
[607Dsub0]
ParameterName=Number of Entries
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=2
PDOMapping=0
[607Dsub1]
ParameterName=Min Position Limit
ObjectType=0x7
DataType=0x0004
AccessType=rw
DefaultValue=-2147483648
ParameterValue=0x80000000
PDOMapping=0
[607Dsub2]
ParameterName=Max Position Limit
ObjectType=0x7
DataType=0x0004
AccessType=rw
DefaultValue=2147483647
ParameterValue=0x7FFFFFFF
PDOMapping=0
[DeviceComissioning]
NodeID=5
"""


def test_vendor_object_shapes_and_signed_hex_values(tmp_path):
    text = XDC_MINIMAL.read_text(encoding="utf-8")
    text = text.replace("</CANopenObjectList>", EPOS3_SHAPES + "</CANopenObjectList>", 1)
    xdc = tmp_path / "epos3_like.xdc"
    xdc.write_text(text, encoding="utf-8")
    od = read_od(xdc)
    assert od[0x2004].data_type == 0x1B and od[0x2004].value == 0x602095000659
    assert od[0x2004].default is None  # defaultValue="": no default, as an empty EDS one
    assert od[0x6041].pdo_mappable and od[0x6040].pdo_mappable  # "TPDO"/"RPDO": mappable
    assert od[0x607D][0].default is None
    assert (od[0x607D][1].default, od[0x607D][1].value) == (-(2**31), -(2**31))
    assert (od[0x607D][2].default, od[0x607D][2].value) == (2**31 - 1, 2**31 - 1)
    assert (od[0x60E3][1].default, od[0x60E3][1].value) == (-1, -1)
    # the DCF saying the same is read the same (canopen alone reads 0x80000000 as 2**31)
    dcf = tmp_path / "signed.dcf"
    dcf.write_text(SIGNED_DCF, encoding="utf-8")
    assert import_od(str(dcf))[0x607D][1].value == 2**31
    ref = read_od(dcf)
    assert (ref[0x607D][1].default, ref[0x607D][1].value) == (-(2**31), -(2**31))
    assert ref[0x607D][2].value == od[0x607D][2].value
    # a log showing the limit as the drive sends it (bytes 00 00 00 80) is the XDC's value
    log = tmp_path / "limit.log"
    log.write_text("(1.0) can0 605#40" + "7D6001" + "00000000\n(1.001) can0 585#437D600100000080\n")
    for ref_file in (xdc, dcf):
        out = cli("diff", str(log), str(ref_file))
        assert out.returncode == 0, out.stdout.decode() + out.stderr.decode()
        assert "same within tolerances" in out.stdout.decode()


# A product's own description: Elcom AS's e-RIO 8xx I/O module (vendor 0x046A), XDD and
# EDS saved by its developer with CANopenEditor on 2023-06-21 and 2023-07-04. Between the
# two the EDS gained 0x2002 and a second 8-bit input 0x6000:02, mapped into TPDO1; the
# rest of the dictionary must agree.
ERIO_XDD = DATA / "e-RIO_8xx.xdd"
ERIO_EDS = DATA / "e-RIO_8xx.eds"


def test_real_product_xdd_agrees_with_its_eds_but_for_the_later_edits():
    from_xdd = variables(read_od(ERIO_XDD, 5))
    from_eds = variables(read_od(ERIO_EDS, 5))
    independent = variables(import_od(str(ERIO_EDS), 5))
    assert set(from_eds) == set(independent)
    added = {(0x2002, 0), (0x2002, 1), (0x2002, 2), (0x2002, 3), (0x6000, 2)}
    assert set(from_eds) - set(from_xdd) == added and set(from_xdd) <= set(from_eds)
    assert len(from_xdd) == 146
    edited = {
        (0x1A00, 0): ("default", 1, 2),  # TPDO1: one mapped object, then two
        (0x1A00, 2): ("default", 0, 0x60000208),
        (0x6000, 0): ("default", 1, 2),  # highest sub-index of the inputs
        (0x6000, 1): ("name", "Digital Inputs", "Digital Inputs 1-8"),
    }
    differences = {}
    for key, x in from_xdd.items():
        for ref in (from_eds[key], independent[key]):
            for attr in ("name", "data_type", "access_type", "pdo_mappable", "min", "max"):
                if getattr(x, attr) != getattr(ref, attr):
                    differences[key] = (attr, getattr(x, attr), getattr(ref, attr))
            if no_default_as_none(x.default) != no_default_as_none(ref.default):
                differences[key] = ("default", x.default, ref.default)
    assert differences == edited
    a, b = load_eds(ERIO_XDD), load_eds(ERIO_EDS)
    identity = (0x046A, 800850, 0x000F0191, "e-RIO 8xx", "e-RIO 8xx")
    for p in (a, b):
        assert (p.vendor_id, p.product_code, p.device_type, p.device_name, p.name) == identity
    tx1_x, tx1_e = (
        [p for p in prof.pdos(5) if (p.direction, p.number) == ("tx", 1)] for prof in (a, b)
    )
    assert [(e.index, e.subindex, e.bits) for e in tx1_x[0].mapping] == [(0x6000, 1, 8)]
    assert [(e.index, e.subindex, e.bits) for e in tx1_e[0].mapping] == [
        (0x6000, 1, 8),
        (0x6000, 2, 8),
    ]
    others = lambda prof: [p for p in prof.pdos(5) if (p.direction, p.number) != ("tx", 1)]  # noqa: E731
    assert others(a) == others(b) and len(others(a)) == 3
    info_x, info_e = read_od(ERIO_XDD).device_information, read_od(ERIO_EDS).device_information
    for attr in ("allowed_baudrates", "nr_of_RXPDO", "nr_of_TXPDO", "LSS_supported", "vendor_name"):
        assert getattr(info_x, attr) == getattr(info_e, attr), attr
    assert info_x.allowed_baudrates == {125_000, 250_000, 500_000} and not info_x.LSS_supported


def test_real_product_xdd_decodes_its_pdos_as_its_eds(tmp_path):
    log = tmp_path / "erio.log"
    log.write_text(  # TPDO2 of node 5: four 16-bit analogue inputs (0x6401:01..04)
        "(1.000000) can0 285#E803D007B80BA00F\n"
    )
    shown = {}
    for ref in (ERIO_XDD, ERIO_EDS):
        out = cli("decode", str(log), "--format", "jsonl", "--eds", f"5={ref}")
        assert out.returncode == 0, out.stderr.decode()
        shown[ref.suffix] = out.stdout.decode()
    assert shown[".xdd"] == shown[".eds"]
    signals = json.loads(shown[".xdd"].splitlines()[0])["signals"]
    assert signals == {f"analog_input_{i}": 1000 * i for i in range(1, 5)}


def test_eds_with_empty_device_info_numbers_is_read_and_a_bad_one_refused(tmp_path):
    """An empty [DeviceInfo] number (CANopenNode's DS301 EDS) is passed over; a number that
    is not one (the e-RIO's older DCF wrote `ProductNumber=e-RIO 8xx`) is still refused in
    one line naming the file."""
    text = XPD_EDS.read_text(encoding="utf-8")
    assert len(variables(read_od(XPD_EDS, 5))) == 176
    bad = tmp_path / "bad.eds"
    bad.write_text(text.replace("\nProductNumber=\n", "\nProductNumber=e-RIO 8xx\n"))
    with pytest.raises(InputError, match=r"bad\.eds: not a valid EDS/DCF: ValueError"):
        read_od(bad)
    log = tmp_path / "bus.log"
    log.write_text(LOG)
    out = cli("decode", str(log), "--eds", f"5={bad}")
    err = out.stderr.decode()
    assert out.returncode == 2 and len(err.strip().splitlines()) == 1 and "bad.eds" in err
