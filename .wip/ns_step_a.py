# Step A: each common/<folder>/ file declares namespace surgsim::<folder>.
import os, re, subprocess
root='/work/main'; os.chdir(root)
files=subprocess.check_output(['git','ls-files','common'],text=True).split()
for f in files:
    if not f.endswith(('.h','.cpp')): continue
    folder=f.split('/')[1]
    s=open(f).read(); o=s
    if folder=='intestine': continue
    s=re.sub(r'^namespace surgsim \{', f'namespace surgsim::{folder} {{', s, flags=re.M)
    s=re.sub(r'^\}  // namespace surgsim$', f'}}  // namespace surgsim::{folder}', s, flags=re.M)
    s=s.replace('namespace surgsim::text {','namespace surgsim::core::text {').replace('}  // namespace surgsim::text','}  // namespace surgsim::core::text')
    s=s.replace('namespace surgsim::mesh_internal {','namespace surgsim::mesh::internal {').replace('}  // namespace surgsim::mesh_internal','}  // namespace surgsim::mesh::internal')
    s=s.replace('namespace surgsim::cli {','namespace surgsim::apps::cli {').replace('}  // namespace surgsim::cli','}  // namespace surgsim::apps::cli')
    if folder=='mesh': s=s.replace('mesh_internal::','internal::')
    if s!=o: open(f,'w').write(s)
# elsewhere
for f in subprocess.check_output(['git','ls-files'],text=True).split():
    if not f.endswith(('.h','.cpp')) or f.startswith('common/'): continue
    s=open(f).read(); o=s
    s=s.replace('mesh_internal::','mesh::internal::').replace('surgsim::text::','surgsim::core::text::').replace('surgsim::cli::','surgsim::apps::cli::')
    if s!=o: open(f,'w').write(s)
