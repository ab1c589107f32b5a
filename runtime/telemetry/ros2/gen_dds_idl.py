#!/usr/bin/python3
"""ROS 2 .msg packages -> the DDS IDL rmw_cyclonedds puts on the wire.

Step 1 is ROS 2's own: rosidl_adapter (Debian: python3-rosidl) turns every .msg into the ROS 2 IDL
(what `rosidl translate` / msg2idl.py write). Step 2 parses that IDL with rosidl_parser and writes
it in the DDS form ROS 2 uses on the wire: type `pkg::msg::Name` becomes `pkg::msg::dds_::Name_`,
every struct @final (XCDR1, no member ids or headers), constants in `Name_Constants`. One output
file holds all packages in dependency order, so idlc compiles it in one go.

usage: gen_dds_idl.py OUT.idl ROS_IDL_DIR PKG_DIR [PKG_DIR ...]
  OUT.idl      the DDS IDL to write (only rewritten when its content changes)
  ROS_IDL_DIR  where the step-1 ROS 2 IDL files go (<pkg>/msg/<Name>.idl)
  PKG_DIR      a ROS 2 interface package (package.xml + msg/*.msg)
Errors name the file and what is wrong, exit status 1.
"""
import pathlib
import sys
import xml.etree.ElementTree as ET

from rosidl_adapter.msg import convert_msg_to_idl
from rosidl_parser import definition as d
from rosidl_parser.parser import parse_idl_file

# ROS 2 IDL basic types -> DDS IDL spelling understood by Cyclone's idlc 0.10 (same wire sizes).
BASIC = {
    'boolean': 'boolean', 'octet': 'octet', 'char': 'char', 'wchar': 'wchar',
    'float': 'float', 'double': 'double', 'long double': 'long double',
    'int8': 'int8', 'uint8': 'uint8', 'int16': 'short', 'uint16': 'unsigned short',
    'int32': 'long', 'uint32': 'unsigned long', 'int64': 'long long',
    'uint64': 'unsigned long long',
    'short': 'short', 'unsigned short': 'unsigned short', 'long': 'long',
    'unsigned long': 'unsigned long', 'long long': 'long long',
    'unsigned long long': 'unsigned long long',
}


def fail(where, what):
    sys.stderr.write(f'gen_dds_idl: {where}: {what}\n')
    sys.exit(1)


def dds_name(nt):
    """pkg::msg::Name -> pkg::msg::dds_::Name_ (rmw_cyclonedds' type name)."""
    return '::'.join(list(nt.namespaces) + ['dds_', nt.name + '_'])


def type_spec(t, where):
    if isinstance(t, d.BasicType):
        if t.typename not in BASIC:
            fail(where, f'basic type {t.typename} has no DDS IDL spelling here')
        return BASIC[t.typename]
    if isinstance(t, d.NamespacedType):
        return dds_name(t)
    if isinstance(t, d.BoundedString):
        return f'string<{t.maximum_size}>'
    if isinstance(t, d.UnboundedString):
        return 'string'
    if isinstance(t, d.BoundedWString):
        return f'wstring<{t.maximum_size}>'
    if isinstance(t, d.UnboundedWString):
        return 'wstring'
    if isinstance(t, d.BoundedSequence):
        return f'sequence<{type_spec(t.value_type, where)}, {t.maximum_size}>'
    if isinstance(t, d.UnboundedSequence):
        return f'sequence<{type_spec(t.value_type, where)}>'
    fail(where, f'type {t!r} is not supported')


def literal(c):
    v = c.value
    if isinstance(v, bool):
        return 'TRUE' if v else 'FALSE'
    if isinstance(v, str):
        return '"' + v.replace('\\', '\\\\').replace('"', '\\"') + '"'
    return repr(v)


def deps_of(msg):
    out = []
    def walk(t):
        if isinstance(t, d.NamespacedType):
            out.append(tuple(t.namespaces) + (t.name,))
        elif isinstance(t, d.AbstractNestedType):
            walk(t.value_type)
    for m in msg.structure.members:
        walk(m.type)
    return out


def main(argv):
    if len(argv) < 4:
        fail('command line', __doc__)
    out = pathlib.Path(argv[1])
    ros_idl_dir = pathlib.Path(argv[2]).absolute()
    messages = {}   # (pkg, 'msg', Name) -> (Message, .msg path)
    for pkg_arg in argv[3:]:
        pkg_dir = pathlib.Path(pkg_arg).absolute()
        manifest = pkg_dir / 'package.xml'
        if not manifest.is_file():
            fail(pkg_dir, 'no package.xml (expected a ROS 2 interface package)')
        name_el = ET.parse(manifest).getroot().find('name')
        if name_el is None or not name_el.text:
            fail(manifest, '<name> missing')
        pkg = name_el.text.strip()
        if pkg != pkg_dir.name:
            fail(manifest, f'package name {pkg} differs from its folder {pkg_dir.name}')
        msg_files = sorted((pkg_dir / 'msg').glob('*.msg'))
        if not msg_files:
            fail(pkg_dir / 'msg', 'no .msg files')
        idl_out = ros_idl_dir / pkg / 'msg'
        idl_out.mkdir(parents=True, exist_ok=True)
        for f in msg_files:
            rel = f.relative_to(pkg_dir)
            try:
                # (It narrates every file on stdout; empy does not let stdout be redirected.)
                idl_file = convert_msg_to_idl(pkg_dir, pkg, rel, idl_out)
                content = parse_idl_file(d.IdlLocator(ros_idl_dir, idl_file.relative_to(ros_idl_dir)))
            except Exception as e:  # noqa: BLE001 (the tools raise many kinds)
                fail(f, f'{type(e).__name__}: {e}')
            for msg in content.content.get_elements_of_type(d.Message):
                nt = msg.structure.namespaced_type
                messages[tuple(nt.namespaces) + (nt.name,)] = (msg, f)

    # Dependency order (a struct after every struct it contains).
    order, state = [], {}
    def visit(key, via):
        if state.get(key) == 'done':
            return
        if state.get(key) == 'active':
            fail(messages[key][1], 'recursive message definition')
        if key not in messages:
            fail(messages[via][1], f'uses {"/".join(key)}, defined in none of the packages given')
        state[key] = 'active'
        for dep in deps_of(messages[key][0]):
            visit(dep, key)
        state[key] = 'done'
        order.append(key)
    for key in sorted(messages):
        visit(key, key)

    lines = ['// GENERATED by runtime/telemetry/ros2/gen_dds_idl.py from the ROS 2 .msg packages in',
             '// runtime/telemetry/ros2 (rosidl_adapter, then the DDS form of rmw_cyclonedds).',
             '// Do not edit: edit the .msg files.', '']
    for key in order:
        msg, src = messages[key]
        nt = msg.structure.namespaced_type
        ns = list(nt.namespaces)
        lines.append(f'// {"/".join(ns + [nt.name])} ({src.parent.parent.name}/msg/{src.name})')
        indent = ''
        for n in ns + ['dds_']:
            lines.append(f'{indent}module {n} {{')
            indent += '  '
        if msg.constants:
            lines.append(f'{indent}module {nt.name}_Constants {{')
            for c in msg.constants:
                lines.append(f'{indent}  const {type_spec(c.type, src)} {c.name} = {literal(c)};')
            lines.append(f'{indent}}};')
        lines.append(f'{indent}@final')
        lines.append(f'{indent}struct {nt.name}_ {{')
        members = msg.structure.members
        if len(members) == 1 and members[0].name == d.EMPTY_STRUCTURE_REQUIRED_MEMBER_NAME:
            lines.append(f'{indent}  uint8 {members[0].name};')
        for m in members:
            where = f'{src}: field {m.name}'
            if isinstance(m.type, d.Array):
                lines.append(f'{indent}  {type_spec(m.type.value_type, where)} {m.name}[{m.type.size}];')
            else:
                lines.append(f'{indent}  {type_spec(m.type, where)} {m.name};')
        lines.append(f'{indent}}};')
        for _ in ns + ['dds_']:
            indent = indent[:-2]
            lines.append(f'{indent}}};')
        lines.append('')
    text = '\n'.join(lines)
    if not out.exists() or out.read_text() != text:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
