#!/usr/bin/python3
"""Regenerates the wire types from the ROS 2 .msg packages and compares them with what the build
compiled; checks they are what rmw_cyclonedds puts on the wire.

usage: regen_idl_test.py GEN_SCRIPT BUILD_IDL IDLC_C_FILE PKG_DIR...
  - GEN_SCRIPT run afresh (rosidl_adapter, then the DDS form) must give BUILD_IDL byte for byte;
  - every struct is @final, named <pkg>::msg::dds_::<Name>_, one per .msg file, and the step-1
    ROS 2 IDL of sensor_msgs/JointState parses (rosidl_parser) to the standard fields;
  - idlc's C (IDLC_C_FILE) registers the type names ROS 2 uses ("pedalwave::msg::dds_::JointState_");
  - a .msg using an unknown type fails naming the file.
Exit 0 when all hold; prints what differs otherwise.
"""
import pathlib
import re
import subprocess
import sys
import tempfile

from rosidl_parser import definition as d
from rosidl_parser.parser import parse_idl_file

failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print('FAIL: ' + what)


def main(argv):
    gen, build_idl, idlc_c = argv[1], pathlib.Path(argv[2]), pathlib.Path(argv[3])
    pkgs = [pathlib.Path(p) for p in argv[4:]]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        out = tmp / 'Telemetry.idl'
        r = subprocess.run(['/usr/bin/python3', gen, str(out), str(tmp / 'rosidl')] + [str(p) for p in pkgs],
                           capture_output=True, text=True)
        check(r.returncode == 0, f'generator failed: {r.stderr}')
        fresh = out.read_text()
        built = build_idl.read_text()
        check(fresh == built, f'regenerated IDL differs from the build\'s {build_idl}')

        # Every .msg has its struct, @final, in <pkg>::msg::dds_ with the trailing underscore.
        structs = re.findall(r'(@final\s*\n\s*)?struct (\w+) \{', fresh)
        names = {n for _, n in structs}
        for final, name in structs:
            check(bool(final), f'struct {name} is not @final')
            check(name.endswith('_'), f'struct {name} lacks the ROS 2 DDS trailing underscore')
        n_msgs = 0
        for p in pkgs:
            for m in sorted((p / 'msg').glob('*.msg')):
                n_msgs += 1
                check(m.stem + '_' in names, f'{p.name}/msg/{m.name}: no struct {m.stem}_')
                check(f'module {p.name} {{' in fresh, f'no module {p.name}')
        check(len(structs) == n_msgs, f'{len(structs)} structs for {n_msgs} .msg files')
        check(fresh.count('module dds_ {') == n_msgs, 'every type sits in a dds_ module')

        # Step 1 is ROS 2's own IDL: sensor_msgs/JointState as the standard defines it.
        js = parse_idl_file(d.IdlLocator(tmp / 'rosidl', 'sensor_msgs/msg/JointState.idl'))
        msg = js.content.get_elements_of_type(d.Message)[0]
        fields = [(mb.name, type(mb.type).__name__) for mb in msg.structure.members]
        check(fields == [('header', 'NamespacedType'), ('name', 'UnboundedSequence'),
                         ('position', 'UnboundedSequence'), ('velocity', 'UnboundedSequence'),
                         ('effort', 'UnboundedSequence')], f'sensor_msgs/JointState fields {fields}')

        # A .msg with an unknown type: the generator fails and names the file.
        bad = tmp / 'bad_msgs'
        (bad / 'msg').mkdir(parents=True)
        (bad / 'package.xml').write_text('<package format="3"><name>bad_msgs</name></package>')
        (bad / 'msg' / 'Broken.msg').write_text('nosuch_msgs/Thing thing\n')
        r = subprocess.run(['/usr/bin/python3', gen, str(tmp / 'bad.idl'), str(tmp / 'rosidl2'), str(bad)],
                           capture_output=True, text=True)
        check(r.returncode == 1 and 'Broken.msg' in r.stderr and 'nosuch_msgs/msg/Thing' in r.stderr,
              f'unknown type: status {r.returncode}, stderr {r.stderr!r}')

    # idlc registered the ROS 2 type names (what DDS matches topics on).
    c = idlc_c.read_text()
    for t in ['pedalwave::msg::dds_::JointState_', 'pedalwave::msg::dds_::CommandAck_',
              'sensor_msgs::msg::dds_::JointState_', 'diagnostic_msgs::msg::dds_::DiagnosticArray_',
              'std_msgs::msg::dds_::String_', 'tf2_msgs::msg::dds_::TFMessage_']:
        check(f'"{t}"' in c, f'idlc output {idlc_c} does not register "{t}"')
    print(f'{n_msgs} messages regenerated and compared; ' + ('FAILED' if failures else 'all checks passed'))
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
