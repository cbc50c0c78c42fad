"""Build the Blind Object Retrieval Diagram of scene FB and list what is wired to what.

Run: python examples/build_bor_diagram.py
"""

from stucco_drake.bor.cli import bor_graphviz
from stucco_drake.bor.diagram import build_bor_diagram

bor = build_bor_diagram("FB", method="stucco", seed=0)
print(f"{bor.diagram.get_name()}: target {bor.target_name!r}, shape {bor.target_shape}")
for system in bor.diagram.GetSystems():
    inputs = [system.get_input_port(i).get_name() for i in range(system.num_input_ports())]
    outputs = [system.get_output_port(i).get_name() for i in range(system.num_output_ports())]
    print(f"  {system.get_name():>22}: in {inputs}, out {outputs}")
# The same wiring as Graphviz source (``stucco-drake diagram`` renders it when Graphviz exists).
print(bor_graphviz("FB").count(" -> "), "connections")
