#!/usr/bin/env bash
# DDS Security for surgsim: makes a TEST certificate authority, one identity per program (haptic node,
# visual node, device driver), the governance and permissions documents signed by that CA, and a Fast DDS profiles
# file with one secure participant profile per program (built-in plugins: PKI-DH authentication, access control by
# signed permissions, AES-GCM cryptography).
#
#   scripts/make_dds_security.sh [OUT_DIR]          (default build/dds_security)
#   FASTRTPS_DEFAULT_PROFILES_FILE=OUT_DIR/secure_profiles.xml build/bin/haptic_node --dds-participant surgsim_secure_haptic
#   FASTRTPS_DEFAULT_PROFILES_FILE=OUT_DIR/secure_profiles.xml build/bin/visual_node --dds-participant surgsim_secure_visual
#   FASTRTPS_DEFAULT_PROFILES_FILE=OUT_DIR/secure_profiles.xml build/bin/surgsim-device-sim --dds-participant surgsim_secure_device
#
# Governance: unauthenticated participants are refused; discovery, liveliness and every topic's data are encrypted
# (AES-GCM), submessages signed (GMAC); every topic needs read and write permission. Permissions: the haptic node
# publishes contact frames, body states, forces and scene info and reads tool commands and visual status; the visual
# node reads those and publishes visual status; the device publishes tool commands and reads forces. Keys are EC
# P-256, valid 10 years. The keys are private material: for a real site make them on the machines that use them, keep
# the CA key offline, and give each machine only its own key.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$root/build/dds_security}
command -v openssl >/dev/null || { echo "make_dds_security: openssl not found (apt-get install openssl)" >&2; exit 1; }
mkdir -p "$out"
out=$(cd "$out" && pwd)
cd "$out"
umask 077

# --- the test CA (signs identities, governance and permissions) ---
openssl ecparam -name prime256v1 -genkey -noout -out ca_key.pem 2>/dev/null
openssl req -new -x509 -key ca_key.pem -out ca_cert.pem -days 3650 -sha256 \
  -subj "/C=ES/O=surgsim test/CN=surgsim test CA" 2>/dev/null

# --- one identity per program ---
cat > ca.cnf <<'EOF'
[ identity ]
basicConstraints = CA:FALSE
keyUsage = digitalSignature, keyAgreement
EOF
subjects=()
for who in haptic visual device; do
  openssl ecparam -name prime256v1 -genkey -noout -out "${who}_key.pem" 2>/dev/null
  openssl req -new -key "${who}_key.pem" -out "${who}.csr" -subj "/C=ES/O=surgsim test/CN=surgsim $who" 2>/dev/null
  openssl x509 -req -in "${who}.csr" -CA ca_cert.pem -CAkey ca_key.pem -CAcreateserial -out "${who}_cert.pem" \
    -days 3650 -sha256 -extfile ca.cnf -extensions identity 2>/dev/null
  rm -f "${who}.csr"
  subjects+=("$(openssl x509 -in "${who}_cert.pem" -noout -subject -nameopt RFC2253 | sed 's/^subject=//')")
done

# --- governance: who may join, what is protected ---
cat > governance.xml <<'EOF'
<?xml version="1.0" encoding="utf-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>232</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>SIGN</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF

# --- permissions: one grant per identity (topic names from idl/dds_support.h) ---
grant() {  # name subject "publish topics" "subscribe topics"
  local topics_pub="" topics_sub=""
  for t in $3; do topics_pub+="<topic>surgsim/$t</topic>"; done
  for t in $4; do topics_sub+="<topic>surgsim/$t</topic>"; done
  cat <<EOF
    <grant name="surgsim_$1">
      <subject_name>$2</subject_name>
      <validity><not_before>2020-01-01T00:00:00</not_before><not_after>2035-01-01T00:00:00</not_after></validity>
      <allow_rule>
        <domains><id_range><min>0</min><max>232</max></id_range></domains>
        <publish><topics>$topics_pub</topics></publish>
        <subscribe><topics>$topics_sub</topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
EOF
}
{
  echo '<?xml version="1.0" encoding="utf-8"?>'
  echo '<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="omg_shared_ca_permissions.xsd">'
  echo '  <permissions>'
  grant haptic "${subjects[0]}" "contact_frame body_state force_feedback scene_info" "tool_command visual_status"
  grant visual "${subjects[1]}" "visual_status" "contact_frame body_state scene_info"
  grant device "${subjects[2]}" "tool_command" "force_feedback"
  echo '  </permissions>'
  echo '</dds>'
} > permissions.xml

# --- sign both documents with the CA (S/MIME, as the DDS Security specification asks) ---
for doc in governance permissions; do
  openssl smime -sign -in "$doc.xml" -text -out "$doc.p7s" -signer ca_cert.pem -inkey ca_key.pem
done

# --- Fast DDS participant profiles, one per program (UDPv4: see README on shared memory after a crash) ---
profile() {  # who
  cat <<EOF
    <participant profile_name="surgsim_secure_$1">
      <rtps>
        <name>surgsim_secure_$1</name>
        <builtin>
          <discovery_config>
            <leaseDuration><sec>5</sec></leaseDuration>
            <leaseAnnouncement><sec>1</sec></leaseAnnouncement>
          </discovery_config>
        </builtin>
        <userTransports><transport_id>surgsim_secure_udp</transport_id></userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <propertiesPolicy>
          <properties>
            <property><name>dds.sec.auth.plugin</name><value>builtin.PKI-DH</value></property>
            <property><name>dds.sec.auth.builtin.PKI-DH.identity_ca</name><value>file://$out/ca_cert.pem</value></property>
            <property><name>dds.sec.auth.builtin.PKI-DH.identity_certificate</name><value>file://$out/$1_cert.pem</value></property>
            <property><name>dds.sec.auth.builtin.PKI-DH.private_key</name><value>file://$out/$1_key.pem</value></property>
            <property><name>dds.sec.access.plugin</name><value>builtin.Access-Permissions</value></property>
            <property><name>dds.sec.access.builtin.Access-Permissions.permissions_ca</name><value>file://$out/ca_cert.pem</value></property>
            <property><name>dds.sec.access.builtin.Access-Permissions.governance</name><value>file://$out/governance.p7s</value></property>
            <property><name>dds.sec.access.builtin.Access-Permissions.permissions</name><value>file://$out/permissions.p7s</value></property>
            <property><name>dds.sec.crypto.plugin</name><value>builtin.AES-GCM-GMAC</value></property>
          </properties>
        </propertiesPolicy>
      </rtps>
    </participant>
EOF
}
{
  echo '<?xml version="1.0" encoding="UTF-8" ?>'
  echo "<!-- Made by scripts/make_dds_security.sh: secure participant profiles (TEST CA in $out). -->"
  echo '<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">'
  echo '  <profiles>'
  echo '    <transport_descriptors>'
  echo '      <transport_descriptor><transport_id>surgsim_secure_udp</transport_id><type>UDPv4</type></transport_descriptor>'
  echo '    </transport_descriptors>'
  for who in haptic visual device; do profile "$who"; done
  echo '  </profiles>'
  echo '</dds>'
} > secure_profiles.xml
chmod 644 ./*.pem ./*.xml ./*.p7s
chmod 600 ./*_key.pem

echo "make_dds_security: test CA, identities (haptic, visual, device), signed governance and permissions in $out"
echo "  profiles: FASTRTPS_DEFAULT_PROFILES_FILE=$out/secure_profiles.xml, --dds-participant surgsim_secure_{haptic,visual,device}"
