#!/usr/bin/python3
"""Drives the official sros2 keystore API (ros2/sros2's Python package, given on sys.path by
run.sh with pedalwave's stand-ins for the three ROS modules it imports) for the sros2 interop test.

  sros2_peer.py keystore KEYSTORE                  sros2.keystore.create_keystore
  sros2_peer.py enclaves KEYSTORE POLICY E...      create_enclave + create_permission(POLICY)
  sros2_peer.py validate KEYSTORE E...             a keystore made by keystore.sh, checked with
                                                   sros2's own means: is_valid_keystore,
                                                   get_enclaves, governance.xml and every
                                                   permissions.xml against sros2's XSDs
  sros2_peer.py compare KEYSTORE_A KEYSTORE_B E... the grants of enclave E in both keystores
                                                   allow the same topics (publish, subscribe)
  sros2_peer.py xsd governance|permissions FILE    FILE against sros2's XSD (exit 1 if invalid)
The domain is ROS_DOMAIN_ID's, as for `ros2 security`. Prints one line per check, "ok ..." or
"FAIL ..."; exit 0 when every check passed, 1 otherwise.
"""
import pathlib
import sys

from lxml import etree

import sros2
import sros2.keystore
from sros2.policy import get_transport_schema

failures = 0


def report(ok, what):
    global failures
    print(('ok    ' if ok else 'FAIL  ') + what, flush=True)
    if not ok:
        failures += 1


def schema(name):
    return etree.XMLSchema(etree.parse(str(get_transport_schema('dds', name))))


def validate_xml(xsd, path, what):
    try:
        xsd.assertValid(etree.parse(str(path)))
        report(True, f'{what}: {path} valid against sros2 {xsd_name[id(xsd)]}')
    except (OSError, etree.XMLSyntaxError, etree.DocumentInvalid) as e:
        report(False, f'{what}: {path}: {e}')


def grant_topics(keystore, enclave):
    """{'publish': set, 'subscribe': set} allowed by the grant for CN=enclave, and its domains."""
    path = pathlib.Path(keystore, 'enclaves', enclave.lstrip('/'), 'permissions.xml')
    doc = etree.parse(str(path))
    grants = [g for g in doc.iterfind('permissions/grant')
              if g.findtext('subject_name') == f'CN={enclave}']
    if len(grants) != 1:
        raise RuntimeError(f'{path}: {len(grants)} grants for CN={enclave}, expected 1')
    out = {'publish': set(), 'subscribe': set(), 'domains': set(), 'default': grants[0].findtext('default')}
    for rule in grants[0].iterfind('allow_rule'):
        out['domains'] |= {d.text for d in rule.iterfind('domains/id')}
        for kind in ('publish', 'subscribe'):
            out[kind] |= {t.text for t in rule.iterfind(f'{kind}/topics/topic')}
    if grants[0].find('deny_rule') is not None:
        out['deny_rule'] = True
    return out


def main(argv):
    if len(argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    cmd, ks = argv[1], pathlib.Path(argv[2])
    if cmd == 'xsd' and len(argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    print(f'sros2 from {pathlib.Path(sros2.__file__).parent}', flush=True)
    if cmd == 'keystore':
        sros2.keystore.create_keystore(ks)
        report(sros2.keystore.is_valid_keystore(ks), f'sros2 create_keystore {ks}')
    elif cmd == 'enclaves':
        policy = pathlib.Path(argv[3])
        for enclave in argv[4:]:
            sros2.keystore.create_enclave(ks, enclave)
            sros2.keystore.create_permission(ks, enclave, policy)
            report(True, f'sros2 create_enclave + create_permission {enclave} (policy {policy.name})')
    elif cmd == 'validate':
        report(sros2.keystore.is_valid_keystore(ks), f'sros2 is_valid_keystore({ks})')
        found = sros2.keystore.get_enclaves(ks)
        report(set(argv[3:]) <= found,
               f'sros2 get_enclaves lists {sorted(argv[3:])} (it found {sorted(found)})')
        validate_xml(governance_xsd, ks / 'enclaves' / 'governance.xml', 'governance')
        for enclave in argv[3:]:
            validate_xml(permissions_xsd,
                         ks / 'enclaves' / enclave.lstrip('/') / 'permissions.xml',
                         f'permissions of {enclave}')
    elif cmd == 'compare':
        other = pathlib.Path(argv[3])
        for enclave in argv[4:]:
            a, b = grant_topics(ks, enclave), grant_topics(other, enclave)
            report(a == b, f'{enclave}: same grant in both keystores'
                   + ('' if a == b else f'\n      {ks}: {a}\n      {other}: {b}'))
    elif cmd == 'xsd':
        kind, path = argv[2], pathlib.Path(argv[3])
        xsd = {'governance': governance_xsd, 'permissions': permissions_xsd}[kind]
        validate_xml(xsd, path, kind)
    else:
        print(__doc__, file=sys.stderr)
        return 2
    return 1 if failures else 0


governance_xsd = schema('governance.xsd')
permissions_xsd = schema('permissions.xsd')
xsd_name = {id(governance_xsd): 'governance.xsd', id(permissions_xsd): 'permissions.xsd'}

if __name__ == '__main__':
    sys.exit(main(sys.argv))
