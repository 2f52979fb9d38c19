"""The built-in actors as the runtime and the driver are handed them: the record of actor classes and component
handles, and the lazy source an entry point passes the runtime. The top of ``aerodaas.actors``."""
